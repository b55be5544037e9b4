import numpy as np
from capture.drivers.azure_kinect import open_mkv
rec = open_mkv("../shared/data/real/azure_kinect_pyk4a/recording.mkv", streams=("depth","ir"))
print(rec.description); print(rec.notes)
out={}
for f in rec.frames():
    print(f.stream, f.frame_number, f.image.shape, f.image.dtype, f.image.min(), f.image.max(), (f.image==0).mean())
    out[f.stream]=f.image
np.savez("/work/notes/simtof/real.npz", **out)
