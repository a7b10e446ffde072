import numpy as np
from bfr_model.params import load_params
from bfr_diagnose.held import _path_fit, _Ball
d = np.load("/tmp/s20/held.npz"); x, y = d["xy"][0], d["xy"][1]
ok = np.isfinite(x); x, y = x[ok], y[ok]
xm = np.median(x)
print("median exc mm", np.median(np.abs(x - xm)) * 1e3)
models = {"nominal": "src/bfr_model/config/rig.yaml", "fin": "docs/diagnosis/fin/corrected_params.yaml",
          "AW": "docs/diagnosis/Actually_worked/corrected_params.yaml", "all8": "docs/diagnosis/ntnu-all-eight/corrected_params.yaml"}
for hw in (3e-3, 6e-3, 10e-3, 15e-3, 20e-3, 25e-3):
    row = [f"hw {hw*1e3:4.0f} mm: measured {(_path_fit(x, y, hw, xm)[2])*1e3:6.1f}"]
    for k, f in models.items():
        b = _Ball(load_params(f), -0.0139)
        pr = b.rest(0.0, 0.085)
        c = b.centre(pr + np.linspace(-0.8, 0.8, 3201))
        row.append(f"{k} {_path_fit(c[:,0], c[:,1], hw, float(b.centre(pr)[0]))[2]*1e3:6.1f}")
    print("  ".join(row))
# measured path heights at x offsets
xr, yr, _ = _path_fit(x, y, 6e-3, xm)
for dx in (-20e-3, -10e-3, -5e-3, 5e-3, 10e-3, 20e-3):
    s = np.abs(x - xr - dx) < 0.5e-3
    row = [f"dx {dx*1e3:+5.0f}: measured rise {(np.median(y[s]) - yr)*1e3:6.2f} mm"]
    for k, f in models.items():
        b = _Ball(load_params(f), -0.0139); pr = b.rest(0.0, 0.085); c0 = b.centre(pr)
        c = b.centre(pr + np.linspace(-0.8, 0.8, 3201))
        j = np.argmin(np.abs(c[:, 0] - c0[0] - dx))
        row.append(f"{k} {(c[j,1]-c0[1])*1e3:6.2f}")
    print("  ".join(row))
