"""SSDD (Shabanov et al., seed report section III-C): a UNet (level 1) and an LSTM-UNet (level 2)
trained on an LQ sensor's depth against an aligned HQ sensor's warped depth with the masked L1 of
eq. 32; level 2 learns from out-of-fold level-1 predictions over sequences."""
