#!/usr/bin/env bash
# Set up rmbench on a fresh Debian/Ubuntu machine: idempotent, safe to re-run.
#  1. as root, install the Debian packages headless MuJoCo rendering needs (EGL and OSMesa)
#     when any is missing;
#  2. create .venv at the repository root;
#  3. install the CPU build of torch first (never a CUDA build), then rmbench with its test,
#     training, text-encoder and planner-backend extras.
set -euo pipefail

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
PYTHON="${PYTHON:-python3}"
TORCH_VERSION="2.13.0"
DEB_PACKAGES=(libegl1 libegl-mesa0 libgl1-mesa-dri libosmesa6 libglib2.0-0)

missing=()
for pkg in "${DEB_PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || missing+=("$pkg")
done
if ((${#missing[@]})); then
  if [ "$(id -u)" -eq 0 ]; then
    echo "[install] apt-get install ${missing[*]}"
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
  else
    echo "[install] warning: missing Debian packages ${missing[*]} (run as root to install them);" \
         "headless rendering may fail" >&2
  fi
fi

"$PYTHON" -c 'import sys; assert sys.version_info >= (3, 11), "rmbench needs Python >= 3.11"' \
  || { echo "[install] $PYTHON is $("$PYTHON" --version 2>&1); rmbench needs Python >= 3.11" >&2; exit 1; }
[ -x .venv/bin/python ] || "$PYTHON" -m venv .venv
PIP=(.venv/bin/python -m pip --disable-pip-version-check)

# torch first and pinned: a later requirement that names torch then finds it satisfied
# instead of pulling the registry's newest (CUDA) build.
if ! .venv/bin/python -c "import torch, sys; sys.exit(torch.__version__.split('+')[0] != '$TORCH_VERSION')" 2>/dev/null; then
  echo "[install] torch==$TORCH_VERSION (CPU)"
  # A CPU wheel on pip's find-links path (as on these machines) if there is one; otherwise
  # PyTorch's CPU-only index. Never plain PyPI, whose Linux torch is the CUDA build.
  tmp="$(mktemp -d)"
  if "${PIP[@]}" download -q --no-deps --no-index "torch==$TORCH_VERSION" -d "$tmp" 2>/dev/null; then
    "${PIP[@]}" install -q "$tmp"/torch-*.whl
  else
    "${PIP[@]}" install -q "torch==$TORCH_VERSION" --index-url https://download.pytorch.org/whl/cpu \
      --extra-index-url https://pypi.org/simple
  fi
  rm -rf "$tmp"
fi
echo "[install] rmbench[test,train,text,vlm]"
"${PIP[@]}" install -q -e ".[test,train,text,vlm]"
.venv/bin/python -c "import rmbench, torch; assert not torch.version.cuda, 'a CUDA torch was installed'"
echo "[install] done: .venv/bin/rmbench --help"
