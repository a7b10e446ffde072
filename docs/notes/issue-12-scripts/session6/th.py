import pickle, sys
import numpy as np
from bfr_model.io import read_recording
from bfr_diagnose.cli import _read
from pathlib import Path
name = sys.argv[1]
suffix = sys.argv[2] if len(sys.argv) > 2 else ""
d = pickle.load(open("/tmp/s7/" + name + suffix + ".pkl", "rb"))
pr = d.parts[0]; prep = pr.prep
runs = _read(Path(f"/work/shared/data/ntnu-rig/{name}.txt"), [], None, False)
rec = runs[0]
print("rec t0", rec.t[0], "prep t0", prep.t[0], "n", rec.n)
th_raw = np.interp(prep.t, rec.t, rec.theta)
diff = prep.theta - th_raw
# align: the raw angle's unknown offset (fusion keeps the mean)
ok = np.isfinite(diff)
print("diff rms %.5f max %.5f" % (np.sqrt(np.mean((diff-np.median(diff))**2)), np.max(np.abs(diff-np.median(diff)))))
# around braking: where u < -0.08
u = prep.u
idx = np.where(u < -0.08)[0]
starts = idx[np.r_[True, np.diff(idx) > 10]]
for s in [s for s in starts if s > 25][:10]:
    w = slice(s-25, s+75)
    dd = diff[w] - np.median(diff)
    print("t %.2f: fused - raw over [-50, +150] ms: min %+.5f max %+.5f" % (prep.t[s], dd.min(), dd.max()))
