"""DDD (Sterzentsenko et al. 2019, seed section III-B): a partial-convolution autoencoder trained
self-supervised on simultaneous multi-view RGB-D frames by splatting colour between the views.

Pure modules: :mod:`~methods.ddd.partial_conv`, :mod:`~methods.ddd.net`, :mod:`~methods.ddd.splatting`,
:mod:`~methods.ddd.losses` (eq. 21-27).
"""
