#!/bin/sh
# Every model variant of bench_model_variants.py, one after the other (about 2.5 min each,
# 2 cores). Run from the repository root; needs ../shared/data/flutter_cbc.
set -e
root=$(pwd)
py=${PYTHON:-$root/.venv/bin/python}
tree=$(mktemp -d)/bayeshopf-variant
git worktree add --detach -q "$tree" HEAD
trap 'git worktree remove --force "$tree"' EXIT
run() {  # label [diff] [harmonics]
    git -C "$tree" checkout -q -- .
    [ -n "$2" ] && git -C "$tree" apply "$root/benchmarks/model_variants/$2"
    PYTHONPATH="$tree" "$py" "$root/benchmarks/bench_model_variants.py" "$1" --harmonics "${3:-4}"
}
run baseline
run fundamental_only "" 1
for d in w_prior_3 quadratic_unfolding free_gain_slope tau_mu_per_group \
         harmonic_error_all harmonic_error_unstable; do
    run "$d" "$d.diff"
done
