#!/usr/bin/env bash
# Set up a virtual environment and run the main job on the embedded default
# (G1, dance1_subject2, smoke profile, artifacts in ./artifacts).
#   EXTRAS=dev,dvc scripts/quickstart.sh     # extras to install (default: dev)
#   SKIP_RUN=1 scripts/quickstart.sh         # set up only
#   SKIP_INSTALL=1 scripts/quickstart.sh     # run only (the environment exists)
set -euo pipefail
cd "$(dirname "$0")/.."

# Where the data is, said before the install: the RD_* variables, a rd-pipeline.toml, or ../shared
# (the team's machines and CI). Found in ../shared, the folders are recorded in rd-pipeline.toml,
# so `.venv/bin/rd-pipeline ...` finds them later in any shell without RD_* variables.
if [ -n "${RD_LAFAN_DIR:-}${RD_RETARGETED_DIR:-}" ]; then
  echo "quickstart: data from the RD_* variables"
elif [ -f rd-pipeline.toml ]; then
  echo "quickstart: data folders from rd-pipeline.toml"
elif [ -d ../shared/data ]; then
  shared="$(cd ../shared && pwd)"
  cat > rd-pipeline.toml <<TOML
# Written by scripts/quickstart.sh: where this checkout's data lives. RD_* variables override it.
[data]
lafan_dir = "$shared/data/lafan1/bvh"
retargeted_dir = "$shared/data/lafan1_retargeted"
robot_assets = "$shared/robots"
TOML
  echo "quickstart: data in $shared, recorded in rd-pipeline.toml"
else
  echo "quickstart: no LAFAN1 data here (RD_LAFAN_DIR, RD_RETARGETED_DIR, rd-pipeline.toml, ../shared): lafan1.zip is downloaded after the install"
fi

if [ -z "${SKIP_INSTALL:-}" ]; then
  if [ ! -x .venv/bin/python ]; then
    python3 -m venv .venv
  fi
  .venv/bin/pip install --quiet --upgrade pip
  # The CPU wheel first: otherwise a torch dependency pulls several GB of CUDA packages.
  .venv/bin/pip install --quiet torch==2.13.0
  # setuptools notes on every mapped editable install that its finder is in use; that is by design here.
  PYTHONWARNINGS=ignore::UserWarning .venv/bin/pip install --quiet -e ".[${EXTRAS:-dev}]"
  # `validate` renders its filmstrip and video with MuJoCo offscreen: EGL, else OSMesa (Mesa's
  # software renderers need no GPU). Without either it still validates and says why it drew nothing.
  if ! ldconfig -p 2>/dev/null | grep -q -E "libEGL\.so\.1|libOSMesa\.so"; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
      echo "quickstart: installing Mesa's EGL for headless rendering (libegl1, libgl1-mesa-dri)"
      apt-get install -y -qq libegl1 libgl1-mesa-dri >/dev/null || echo "quickstart: could not install libegl1; validation will draw no pictures"
    else
      echo "quickstart: no EGL or OSMesa library found; install libegl1 (or libosmesa6) for validation's pictures"
    fi
  fi
fi

if [ -z "${SKIP_RUN:-}" ]; then
  if ! .venv/bin/rd-pipeline motions >/dev/null 2>&1; then
    echo "quickstart: no LAFAN1 data found; downloading it (rd-pipeline fetch-lafan)"
    if ! .venv/bin/rd-pipeline fetch-lafan; then
      echo "quickstart: no motion data: run \`.venv/bin/rd-pipeline fetch-lafan\` where lafan1.zip can be downloaded, or set RD_LAFAN_DIR (LAFAN1 BVH files) or RD_RETARGETED_DIR (dataset CSVs), and RD_ROBOT_ASSETS (robot models), as variables or in rd-pipeline.toml, and rerun" >&2
      exit 1
    fi
  fi
  .venv/bin/rd-pipeline run
fi
