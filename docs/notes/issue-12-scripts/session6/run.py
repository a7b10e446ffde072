import pickle, sys, time
from pathlib import Path
from bfr_diagnose.cli import _read, build_parser, _options
from bfr_diagnose.api import diagnose_recordings
from bfr_model.params import load_params
name = sys.argv[1]
p = Path(f"/work/shared/data/ntnu-rig/{name}.txt")
if not p.exists():
    p = Path(f"../shared/data/ntnu-rig/{name}.txt")
args = build_parser().parse_args([str(p)])
runs = _read(p, [], None, False)
base = load_params(args.params)
opts = _options(args, runs[0])
t0 = time.time()
d = diagnose_recordings([(str(p), runs)], base, opts, progress=lambda m: print(m, file=sys.stderr))
print("wall", time.time() - t0)
import bfr_diagnose.identify as I
with open(f"/tmp/s7/{name}.pkl", "wb") as f:
    pickle.dump(d, f)
print(d.findings["parts"][0]["metrics"]["prediction_improvement"] if "parts" in d.findings else list(d.findings))
