#!/usr/bin/env bash
# Reference values for tests/methods/test_counting_vs_glab.py: gLAB's own SBAS summary of the
# EGNOS day, and the per-epoch output that overbound reads. Runs an existing gLAB binary
# (gAGE/UPC gLAB v6.0.0; how it was obtained is in tests/data/glab/PROVENANCE.md): this script
# does not build it.
#
#   tests/reference/run_glab_fullday.sh /path/to/gLAB_linux ../shared/data/egnos-ems-prn123-2019-014
set -euo pipefail
glab=${1:?path to the gLAB binary}
data=${2:?path to shared/data/egnos-ems-prn123-2019-014}
out=$(cd "$(dirname "$0")/../data/glab" && pwd)
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
gunzip -c "$data/synthetic-obs/SYNT0140.19o.gz" > "$work/SYNT0140.19o"
cat "$data"/ems/h*.ems > "$work/egnos123_2019014.ems"
args=(-input:obs "$work/SYNT0140.19o" -input:nav "$data/brdc0140.19n" -input:sbas1f "$work/egnos123_2019014.ems"
      -pre:setrecpos 4627851.2711 119640.7753 4372993.8468)
"$glab" "${args[@]}" -print:none -print:info -print:output -print:sbasout -output:file "$work/full.out"
gzip -9 -n -c "$work/full.out" > "$out/synt0140_egnos123_v6_fullday.glab.gz"
"$glab" "${args[@]}" -print:sumonly -output:file "$out/synt0140_egnos123_v6_fullday.summary.txt"
