#!/usr/bin/env bash
# Set up a virtual environment and run the main job on the embedded default
# (G1, dance1_subject2, smoke profile, artifacts in ./artifacts).
#   EXTRAS=dev,dvc scripts/quickstart.sh     # extras to install (default: dev)
#   SKIP_RUN=1 scripts/quickstart.sh         # set up only
#   SKIP_INSTALL=1 scripts/quickstart.sh     # run only (the environment exists)
set -euo pipefail
cd "$(dirname "$0")/.."

if [ -z "${SKIP_INSTALL:-}" ]; then
  if [ ! -x .venv/bin/python ]; then
    python3 -m venv .venv
  fi
  .venv/bin/pip install --quiet --upgrade pip
  # The CPU wheel first: otherwise a torch dependency pulls several GB of CUDA packages.
  .venv/bin/pip install --quiet torch==2.13.0
  # setuptools notes on every mapped editable install that its finder is in use; that is by design here.
  PYTHONWARNINGS=ignore::UserWarning .venv/bin/pip install --quiet -e ".[${EXTRAS:-dev}]"
fi

# On the team's machines and in CI the data sits in ../shared; elsewhere set the variables yourself
# (README: "Where data comes from").
if [ -d ../shared/data ]; then
  export RD_LAFAN_DIR="${RD_LAFAN_DIR:-$(cd ../shared/data/lafan1/bvh && pwd)}"
  export RD_RETARGETED_DIR="${RD_RETARGETED_DIR:-$(cd ../shared/data/lafan1_retargeted && pwd)}"
  export RD_ROBOT_ASSETS="${RD_ROBOT_ASSETS:-$(cd ../shared/robots && pwd)}"
fi

if [ -z "${SKIP_RUN:-}" ]; then
  if ! .venv/bin/rd-pipeline motions >/dev/null 2>&1; then
    echo "quickstart: no LAFAN1 data found; downloading it (rd-pipeline fetch-lafan)"
    if ! .venv/bin/rd-pipeline fetch-lafan; then
      echo "quickstart: no motion data: run \`.venv/bin/rd-pipeline fetch-lafan\` where lafan1.zip can be downloaded, or set RD_LAFAN_DIR (LAFAN1 BVH files) or RD_RETARGETED_DIR (dataset CSVs) and rerun" >&2
      exit 1
    fi
  fi
  .venv/bin/rd-pipeline run
fi
