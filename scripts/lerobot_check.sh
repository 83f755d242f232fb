#!/usr/bin/env bash
# rmbench inside LeRobot, end to end: a LeRobot environment of its own, a small rmbench
# dataset, LeRobot's ACT trained on it for a few steps with lerobot-train, evaluated on one
# rmbench episode with lerobot-eval, and the same checkpoint evaluated by rmbench eval (the
# lerobot: policy spec) and through rmbench serve. Exits non-zero on the first failure.
#
#   bash scripts/lerobot_check.sh            # environment in .venv-lerobot, work in runs/lerobot_check
#
# RMBENCH_LEROBOT_VENV and RMBENCH_LEROBOT_WORK move them; LEROBOT_VERSION picks LeRobot's
# release (0.4.4: the newest for Python 3.11). Packages come from pip's configured index.
# As root, FFmpeg's shared libraries (LeRobot's video decoding, torchcodec, links them) are
# installed from Debian's packages when missing.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="${RMBENCH_LEROBOT_VENV:-$ROOT/.venv-lerobot}"
WORK="${RMBENCH_LEROBOT_WORK:-$ROOT/runs/lerobot_check}"
PY="${PYTHON:-python3.11}"
LEROBOT_VERSION="${LEROBOT_VERSION:-0.4.4}"
TASK=put_back_block
START=$(date +%s)
step() { echo "== $(( $(date +%s) - START ))s: $*"; }

step "FFmpeg shared libraries"
if ! ldconfig -p | grep -q 'libavutil\.so'; then
    if [ "$(id -u)" = 0 ]; then
        apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq ffmpeg >/dev/null
    else
        echo "lerobot_check: FFmpeg's shared libraries are missing (apt-get install ffmpeg, as root)" >&2
        exit 1
    fi
fi

step "LeRobot $LEROBOT_VERSION environment in $VENV"
if [ ! -x "$VENV/bin/lerobot-eval" ] || ! "$VENV/bin/python" -c "import rmbench.lerobot.config" 2>/dev/null; then
    [ -x "$VENV/bin/python" ] || "$PY" -m venv "$VENV"
    "$VENV/bin/pip" install -q "lerobot==$LEROBOT_VERSION" -e "$ROOT[lerobot]"
fi
export PATH="$VENV/bin:$PATH"
# nothing is fetched at run time: the dataset is local, ACT's backbone starts untrained
export HF_HUB_OFFLINE=1 HF_DATASETS_OFFLINE=1 WANDB_MODE=disabled MUJOCO_GL="${MUJOCO_GL:-egl}"

rm -rf "$WORK" && mkdir -p "$WORK"
# the head camera at rmbench's default resolution: rmbench eval's env renders the same frames
# lerobot-eval's does, so the three evaluations below run the same episode action for action
step "an rmbench dataset: 3 demonstrations, the head camera"
rmbench collect "$TASK" --episodes 3 --seed 0 --cameras head --out "$WORK/data"
rmbench dataset check "$WORK/data"

step "lerobot-train: ACT, 5 steps, on the rmbench dataset as it is"
lerobot-train --dataset.repo_id=rmbench/"$TASK" --dataset.root="$WORK/data" \
    --policy.type=act --policy.pretrained_backbone_weights=null --policy.device=cpu \
    --policy.push_to_hub=false --policy.chunk_size=20 --policy.n_action_steps=20 \
    --steps=5 --batch_size=4 --num_workers=0 --save_freq=5 --log_freq=5 \
    --eval_freq=0 --wandb.enable=false --output_dir="$WORK/train"
CKPT="$WORK/train/checkpoints/last/pretrained_model"

step "lerobot-eval: one rmbench episode (rmbench's first verified seed, its success)"
lerobot-eval --policy.path="$CKPT" --policy.device=cpu \
    --env.discover_packages_path=rmbench.lerobot --env.type=rmbench --env.task="$TASK" \
    --env.cameras=head --env.obs_type=pixels_environment_state_agent_pos --eval.n_episodes=1 --eval.batch_size=1 --seed=0 --output_dir="$WORK/lerobot_eval"

step "rmbench eval of the same checkpoint (lerobot: spec), the same episode"
rmbench eval --task "$TASK" --policy "lerobot:$CKPT" --episodes 1 --seed 0 --video none \
    --out "$WORK/rmbench_eval"

step "rmbench eval through rmbench serve (remote:), the same episode"
PORT=$("$VENV/bin/python" -c "import socket; s = socket.socket(); s.bind(('127.0.0.1', 0)); print(s.getsockname()[1])")
rmbench serve --policy "lerobot:$CKPT" --task "$TASK" --port "$PORT" > "$WORK/serve.log" 2>&1 &
SERVER=$!
trap 'kill "$SERVER" 2>/dev/null || true' EXIT
for _ in $(seq 120); do
    grep -q serving "$WORK/serve.log" 2>/dev/null && break
    sleep 1
done
rmbench eval --task "$TASK" --policy "remote:ws://127.0.0.1:$PORT" --episodes 1 --seed 0 \
    --video none --out "$WORK/remote_eval"

step "the three evaluations ran the same episode"
"$VENV/bin/python" - "$WORK" <<'EOF'
import json
import sys
from pathlib import Path

work = Path(sys.argv[1])
metrics = json.loads((work / "lerobot_eval" / "eval_info.json").read_text())["per_task"][0]["metrics"]
episode = {"success": metrics["successes"][0], "sum_reward": metrics["sum_rewards"][0]}
records = {name: json.loads((work / name / "put_back_block" / "episodes.jsonl").read_text()
                            .splitlines()[0]) for name in ("rmbench_eval", "remote_eval")}
# rmbench's reward is the increase of the task's progress: an episode's return is its best
print(f"lerobot-eval: success {episode['success']}, return {episode['sum_reward']:.6f}")
for name, r in records.items():
    print(f"{name}: success {r['success']}, best progress {r['progress']} on rmbench seed "
          f"{r['seed']} ({r['reason']}, {r['steps']} steps)")
for name, r in records.items():
    if r["reason"] == "policy_error":
        sys.exit(f"lerobot_check: {name} ended in a policy error: {r['message']}")
    if r["success"] != episode["success"] or abs(r["progress"] - episode["sum_reward"]) > 1e-5:
        sys.exit(f"lerobot_check: lerobot-eval and {name} ran different episodes")
same = ("success", "progress", "steps", "reason", "seed")
if any(records["rmbench_eval"][k] != records["remote_eval"][k] for k in same):
    sys.exit("lerobot_check: the served checkpoint ran another episode than the local one")
EOF
step "done"
