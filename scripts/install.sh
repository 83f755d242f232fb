#!/usr/bin/env bash
# Set up rmbench on a fresh Debian/Ubuntu machine: idempotent, safe to re-run.
#  1. as root, install the Debian packages headless MuJoCo rendering needs (EGL and OSMesa)
#     when any is missing;
#  2. create .venv at the repository root;
#  3. install the CPU build of torch first (never a CUDA build), then rmbench with its test,
#     training, text-encoder, ImageNet-backbone and planner-backend extras.
# Packages come from pip's configured index (pip config, PIP_INDEX_URL, ...). torch alone can
# come from another: RMBENCH_TORCH_INDEX=URL (docs/getting-started.md).
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

# torch first, pinned and the CPU build: a later requirement that names torch then finds it
# satisfied instead of pulling the index's newest (CUDA) build.
torch_ok() {
  .venv/bin/python -c "import sys, torch
sys.exit(torch.__version__.split('+')[0] != '$TORCH_VERSION' or bool(torch.version.cuda))" 2>/dev/null
}
if ! torch_ok; then
  tmp="$(mktemp -d)"
  if [ -n "${RMBENCH_TORCH_INDEX:-}" ]; then
    # The index the user named (PyTorch's CPU-only wheel index, say) serves torch alone; its
    # dependencies then come from pip's configured index. --force-reinstall replaces a CUDA
    # build of the same version, which pip would otherwise count as satisfying the pin.
    echo "[install] torch==$TORCH_VERSION (CPU) from RMBENCH_TORCH_INDEX=$RMBENCH_TORCH_INDEX"
    "${PIP[@]}" install -q --no-deps --force-reinstall --index-url "$RMBENCH_TORCH_INDEX" \
      "torch==$TORCH_VERSION"
    "${PIP[@]}" install -q "torch==$TORCH_VERSION"
  elif "${PIP[@]}" download -q --no-deps --no-index "torch==$TORCH_VERSION" -d "$tmp" 2>/dev/null; then
    # a CPU wheel on pip's find-links path (as on these machines)
    echo "[install] torch==$TORCH_VERSION (CPU) from a local wheel"
    "${PIP[@]}" install -q "$tmp"/torch-*.whl
  else
    echo "[install] torch==$TORCH_VERSION from pip's configured index"
    "${PIP[@]}" install -q "torch==$TORCH_VERSION"
  fi
  rm -rf "$tmp"
  # On Linux the default index's torch is the CUDA build: say how to get the CPU one.
  torch_ok || { echo "[install] pip's index gave no CPU build of torch==$TORCH_VERSION; set" \
    "RMBENCH_TORCH_INDEX to a CPU wheel index (README.md, set-up) and re-run" >&2; exit 1; }
fi
echo "[install] rmbench[test,train,text,vlm,vision]"
"${PIP[@]}" install -q -e ".[test,train,text,vlm,vision]"
.venv/bin/python -c "import rmbench, torch; assert not torch.version.cuda, 'a CUDA torch was installed'"
echo "[install] done: .venv/bin/rmbench --help"
