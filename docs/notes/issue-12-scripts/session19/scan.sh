#!/usr/bin/env bash
# The whole diagnosis of Actually_worked with only the groove (hence the rolling radius)
# changed in the nominal model (docs/diagnosis.md, "What the creep stands in for").
# Writes /tmp/s19/aw_d<D>.json; compare with `python show.py /tmp/s19/aw_d*.json`. ~90 s each.
set -e
cd "$(dirname "$0")/../../../.."
source scripts/env.sh
mkdir -p /tmp/s19
for d in 8.8 12.0 15.0 18.0 21.0; do  # [mm]; YAML 1.1 needs the dot in 12.0e-3
  sed "s/plate_distance: 25.5e-3/plate_distance: ${d}e-3/" src/bfr_model/config/rig.yaml \
    > /tmp/s19/d$d.yaml
  scripts/bfr diagnose ../shared/data/ntnu-rig/Actually_worked.txt --params /tmp/s19/d$d.yaml \
    --out-dir /tmp/s19/aw_d$d --force --no-plots --json > /tmp/s19/aw_d$d.json
done
