#!/usr/bin/env bash
# One Slurm array task per training stage of dvc.yaml (train@<w> for each train.pi_weights,
# then train_baseline), each in its own clone: trains that stage and pushes its outputs and
# run-cache to the DVC remote. Afterwards a coordinator's `dvc repro` restores every training
# instead of running it (docs/sweep.md).
#
#   sbatch jobs/slurm_train.sh          # from a checkout whose dvc.lock records the features
#
# PIMANN_REMOTE: the DVC remote every task shares (default: the checkout's own, made
# absolute). --array: one task per training stage, 0 to len(train.pi_weights) (the test suite
# checks it against params.yaml).
#SBATCH --job-name=pimann-train
#SBATCH --array=0-5
#SBATCH --cpus-per-task=2
#SBATCH --mem=8G
#SBATCH --time=24:00:00
#SBATCH --output=pimann-train-%A_%a.log
set -euo pipefail
checkout="${SLURM_SUBMIT_DIR:?submit from the checkout}"
remote="${PIMANN_REMOTE:-$(cd "$checkout" && dvc remote list | awk '$1 == "sweep" {print $2}')}"
work="${TMPDIR:-/tmp}/pimann-${SLURM_ARRAY_JOB_ID}-${SLURM_ARRAY_TASK_ID}"
git clone -q "$checkout" "$work"
# dvc.yaml tracks ../shared: the checkout's, beside the clone too
[ -e "$(dirname "$work")/shared" ] || ln -s "$(cd "$checkout/.." && pwd)/shared" "$(dirname "$work")/shared"
cd "$work"
dvc remote modify --local sweep url "$remote"
mapfile -t stages < <(dvc stage list --name-only | grep -E '^train(@|_baseline$)')
stage="${stages[$SLURM_ARRAY_TASK_ID]:?no training stage $SLURM_ARRAY_TASK_ID}"
export PIMANN_THREADS="${SLURM_CPUS_PER_TASK:-1}" OMP_NUM_THREADS="${SLURM_CPUS_PER_TASK:-1}"
dvc pull features
dvc repro -s "$stage"
dvc push "$stage"
dvc push --run-cache
