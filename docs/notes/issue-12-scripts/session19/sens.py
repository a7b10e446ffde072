import pickle, sys, dataclasses, numpy as np
from bfr_diagnose import grip as G
from bfr_diagnose.locate import causal_prediction_errors
c = pickle.load(open("/tmp/s19/Actually_worked.pkl", "rb"))
s = c["sensor"]; print(s)
law = G.SlipLaw(kind="creep", value=0.1)
field = sys.argv[1]
for d in [float(v) for v in sys.argv[2].split(",")]:
    s2 = dataclasses.replace(s, **{field: getattr(s, field) + d})
    for lw in (law,):
        r = causal_prediction_errors(c["prep"], c["corrected"], c["phi"], c["phi_dot"], s2, c["test_t"], slip=lw)
        print(f"{field} {d:+g}: {'creep' if lw else 'rolling'} causal ball {r['rmse']['ball_angle']:.5f} theta {r['rmse']['theta']:.5f}", flush=True)
