#!/bin/sh
# Model variants of bench_model_variants.py, one after the other (about 2.5 min each,
# 2 cores): all of them, or the labels given. Run from the repository root; needs
# ../shared/data/flutter_cbc.
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
if [ $# -eq 0 ]; then   # every variant; or name the labels to run
    set -- baseline fundamental_only w_prior_3 quadratic_unfolding free_gain_slope \
        free_gain_and_cubic_mu tau_mu_per_group harmonic_error_all harmonic_error_unstable \
        tight_model_error
fi
for d in "$@"; do
    case $d in
        baseline) run baseline ;;
        fundamental_only) run fundamental_only "" 1 ;;
        *) run "$d" "$d.diff" ;;
    esac
done
