"""``bfr read RECORDING...``: what a recording holds and what its reader could not use.

Reads each recording with the project's readers (rig log, CSV, ROS 2 bag) and prints its
read account (:class:`bfr_model.io.account.ReadAccount`) in one line on stderr: samples and
seconds used against present, the samples dropped by cause (corrupt, truncated, duplicate,
out of order, out of range, non-finite) and what was done about each. ``--json`` prints the
accounts and a summary of each recording on stdout.

Exit codes: 0 every recording read (within the 1 % rule, or ``--allow-partial``), 2 bad
input (one line on stderr: unreadable, wrong topic types, more than 1 % lost, ...).

Example::

    bfr read ../shared/data/ntnu-rig/fin.txt run_bag --json
"""

from __future__ import annotations

import argparse
import json
import sys
import warnings
from pathlib import Path

from bfr_model.io import account_line, read_runs
from bfr_model.params import ParameterError

__all__ = ["build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``bfr read``."""
    p = argparse.ArgumentParser(
        prog="bfr read",
        description="Read recordings (rig logs .txt, CSV, ROS 2 bags) and print what each "
                    "reader used against what the file holds, by cause.",
        epilog="Example: bfr read ../shared/data/ntnu-rig/fin.txt --json")
    p.add_argument("recordings", type=Path, nargs="+", metavar="recording",
                   help="recording file or bag directory")
    p.add_argument("--allow-partial", action="store_true",
                   help="accept a recording even when more than 1 %% of its samples could not "
                        "be read")
    p.add_argument("--topic", action="append", default=[], metavar="NAME=TOPIC",
                   help="remap a bag topic (e.g. joint_states=/rig/joint_states)")
    p.add_argument("--json", action="store_true", help="print the accounts as JSON")
    return p


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``bfr read``; returns the process exit code."""
    args = build_parser().parse_args(argv)
    remap = {}
    for item in args.topic:
        if "=" not in item:
            print(f"bfr read: error: --topic {item!r}: expected NAME=TOPIC", file=sys.stderr)
            return 2
        k, v = item.split("=", 1)
        remap[k.strip()] = v.strip()
    out = []
    for path in args.recordings:
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # what the reader found is in its account
                runs = read_runs(path, allow_partial=args.allow_partial,
                                 topic_map=remap or None)
        except (ValueError, OSError, ParameterError) as exc:
            print(f"bfr read: error: {exc}", file=sys.stderr)
            return 2
        print(f"bfr read: {account_line(runs)}", file=sys.stderr, flush=True)
        out.append({"recording": str(path),
                    "runs": [{"account": r.meta.get("read_account"), **r.summary()}
                             for r in runs]})
    if args.json:
        print(json.dumps(out, default=str))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
