"""Run bfr diagnose on a log and pickle the grip inputs (probe)."""
import pickle, sys
from bfr_diagnose import api, cli
cap = {}
_g = api.grip
def grip(prep, corrected, nominal, sensor, phi, phi_dot, test_t, *a, **k):
    cap.update(prep=prep, corrected=corrected, nominal=nominal, sensor=sensor, phi=phi,
               phi_dot=phi_dot, test_t=test_t)
    out = _g(prep, corrected, nominal, sensor, phi, phi_dot, test_t, *a, **k)
    cap['grip'] = out
    return out
api.grip = grip
name = sys.argv[1]
rc = cli.main([f"../shared/data/ntnu-rig/{name}.txt", "--out-dir", f"/tmp/s19/{name}",
               "--force", "--no-plots"])
pickle.dump(cap, open(f"/tmp/s19/{name}.pkl", "wb"))
print("rc", rc)
