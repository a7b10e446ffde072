"""A/B CPU time per 1 ms call on the smooth track: old (HEAD) vs new contact model, interleaved."""
import sys, time, numpy as np
sys.path.insert(0, "/tmp/p16/old")
from bfr_model.params import load_params
from bfr_model.contact import ContactModel as New
from oldbfr.contact import ContactModel as Old
P = load_params()
models = {"old": Old(P), "new": New(P)}
def run(m, n=200):
    x = m.state_from_rigid(np.array([0.0, 0.3, 0.0, 0.0]))
    t0 = time.process_time()
    for i in range(n): x = m.step(x, 0.0, 1e-3)
    return (time.process_time() - t0) / n
for m in models.values(): run(m, 5)
res = {k: [] for k in models}
for r in range(int(sys.argv[1]) if len(sys.argv) > 1 else 7):
    for k, m in models.items(): res[k].append(run(m))
for k, v in res.items(): print(f"{k}: CPU per 1 ms call median {1e6*np.median(v):.1f} us  [{1e6*min(v):.1f}, {1e6*max(v):.1f}]  RTF(cpu) {1e-3/np.median(v):.2f}")
r = np.array(res["new"]) / np.array(res["old"])
print("ratio new/old per repeat: median", np.median(r), r.round(2))
