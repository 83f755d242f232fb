"""The state observation (``obs_type="environment_state_agent_pos"``): every task's vector has
the documented length and order, reads the simulator's poses, and hides what the head camera
cannot see (checked against the camera's own segmentation)."""

import json
import re
from pathlib import Path

import mujoco
import numpy as np
import pytest

import rmbench
from rmbench.experts import make_expert
from rmbench.sim.simulator import data_renderer
from rmbench.tasks import get_task
from rmbench.tasks.state import bounds

STATE = "environment_state_agent_pos"
LENGTHS = {"battery_try": 21, "blocks_ranking_try": 30, "cover_blocks": 42,
           "observe_and_pickup": 86, "press_button": 15, "put_back_block": 16,
           "rearrange_blocks": 17, "swap_T": 10, "swap_blocks": 19}


def _leftmost(pieces, data):
    return min(pieces, key=lambda p: data.xpos[p.body_id][0])


# task -> (entry prefix, the piece whose world position those entries must hold)
SPOT = {
    "battery_try": ("battery_left", lambda t: _leftmost(t.batteries, t.data)),
    "blocks_ranking_try": ("cube_left", lambda t: _leftmost(t.cubes, t.data)),
    "cover_blocks": ("cover_left", lambda t: _leftmost(t.covers, t.data)),
    "observe_and_pickup": ("object3", lambda t: t.objects[3]),
    "put_back_block": ("cube", lambda t: t.cube),
    "rearrange_blocks": ("cube_right", lambda t: max(t.cubes, key=lambda c: c.pos(t.data)[0])),
    "swap_T": ("t_blue", lambda t: max(t.blocks, key=lambda b: t.model.geom_rgba[b.geom_id][2])),
    "swap_blocks": ("cube_left", lambda t: _leftmost(t.cubes, t.data)),
}


def test_state_vector_layout(task_name):
    cls = get_task(task_name)
    names = cls.state_names
    assert len(names) == LENGTHS[task_name] and len(set(names)) == len(names)
    env = rmbench.make(task_name, obs_type=STATE)
    obs, _ = env.reset(seed=100003)
    state = obs["environment_state"]
    assert state.shape == (len(names),) and state.dtype == np.float64
    assert np.isfinite(state).all()
    assert env.observation_space.contains(obs)
    task = env.unwrapped.task
    named = dict(zip(names, state, strict=True))
    if task_name in SPOT:
        prefix, piece = SPOT[task_name]
        pos = piece(task).pos(task.data)
        assert [named[f"{prefix}_{c}"] for c in "xyz"] == pytest.approx(pos, abs=1e-12)
    if task_name == "swap_T":  # a T's heading: cos/sin of its yaw
        blue = SPOT["swap_T"][1](task)
        yaw = blue.yaw(task.data)
        assert (named["t_blue_cos_yaw"], named["t_blue_sin_yaw"]) == pytest.approx(
            (np.cos(yaw), np.sin(yaw)))
    if task_name == "press_button":  # positions of fixed pieces and the digits the tiles show
        assert (named["button_middle_x"], named["button_middle_y"]) == pytest.approx(
            task.middle.xy(task.model))
        assert (named["tile_left_digit"], named["tile_middle_digit"]) == (task.d1, task.d2)
    env.close()


def test_state_follows_the_episode_and_stays_in_its_space():
    """Along an expert episode the vector tracks the sim (the cube's pose, carried away from
    its mat) and stays finite and inside the declared Box."""
    env = rmbench.make("put_back_block", obs_type=STATE)
    expert = make_expert(env)
    obs, info = env.reset(seed=100000)
    expert.reset(info["instruction"], info)
    cube = [get_task("put_back_block").state_names.index(f"cube_{c}") for c in "xyz"]
    start = obs["environment_state"][cube]
    travelled = 0.0
    for _ in range(150):
        obs, _, terminated, truncated, _ = env.step(expert.act(obs))
        assert env.observation_space.contains(obs)
        pos = env.unwrapped.task.cube.pos(env.unwrapped.sim.data)
        assert obs["environment_state"][cube] == pytest.approx(pos, abs=1e-12)
        travelled = max(travelled, float(np.linalg.norm(pos - start)))
        if terminated or truncated:
            break
    assert travelled > 0.05
    env.close()


def test_bounds_follow_the_names():
    low, high = bounds(("a_x", "a_cos4yaw", "b_plus_sin_yaw", "b_depth", "t_digit",
                        "lamp_red", "c_r"))
    assert low.tolist() == [-5, -1, -1, -0.05, 0, 0, 0]
    assert high.tolist() == [5, 1, 1, 0.05, 9, 1, 1]


# ------------------------------------------------------- what the camera cannot see
def _geom_pixels(renderer, data) -> np.ndarray:
    """The head camera's segmentation: the geom id of each pixel (-1 for anything else)."""
    renderer.update_scene(data, camera="head")
    seg = renderer.render()
    return np.where(seg[..., 1] == int(mujoco.mjtObj.mjOBJ_GEOM), seg[..., 0], -1)


@pytest.mark.parametrize("task_name, seed", [("cover_blocks", 100000),
                                             ("observe_and_pickup", 100000)])
def test_visibility_flags_agree_with_the_head_camera(task_name, seed):
    """A flag says hidden only when the head camera's segmentation shows next to nothing of
    the piece, and visible only when it shows some of it. Measured at 320x240 (seeds
    100000-100002, every step): a cover_blocks cube (about 170 pixels in the open) shows at
    most 9 pixels while flagged hidden (the rim of a cover coming down passes the cube's top)
    and at least 1 while flagged visible; the reference object 0 and 140.
    """
    env = rmbench.make(task_name, obs_type=STATE)
    u = env.unwrapped
    task, model, data = u.task, u.sim.model, u.sim.data
    names = type(task).state_names
    renderer = data_renderer(model, 320, 240)
    renderer.enable_segmentation_rendering()
    expert = make_expert(env)
    obs, info = env.reset(seed=seed)
    expert.reset(info["instruction"], info)
    if task_name == "cover_blocks":
        pieces = [(f"cube_{p}_visible", {c.geom_id}) for p, c in
                  zip(("left", "middle", "right"), task.cubes, strict=True)]  # cubes never move
    else:
        pieces = [("reference_visible", set(task.reference.geom_ids.values()))]
    was_hidden, shown_again = set(), False  # until a hidden piece shows again (an uncover)
    try:
        for step in range(u.step_limit):
            if step % 3 == 0:
                geom_of_pixel = _geom_pixels(renderer, data)
                for flag, geoms in pieces:
                    visible = bool(obs["environment_state"][names.index(flag)])
                    px = int(np.isin(geom_of_pixel, list(geoms)).sum())
                    assert (px >= 1) if visible else (px <= 10), (step, flag, px)
                    shown_again |= visible and flag in was_hidden
                    if not visible:
                        was_hidden.add(flag)
            obs, _, terminated, truncated, info = env.step(expert.act(obs))
            if terminated or truncated or shown_again:
                break
        assert was_hidden == {flag for flag, _ in pieces}
        assert shown_again or info["is_success"]
    finally:
        renderer.close()
        env.close()


def test_docs_list_every_entry_in_order():
    """docs/reference/observations.md: one table per task, its rows' piece and entries spelling
    out ``state_names`` in order."""
    text = (Path(__file__).parents[1] / "docs" / "reference" / "observations.md").read_text()
    sections = re.split(r"^### ", text, flags=re.M)[1:]
    documented = {}
    for section in sections:
        task = section.split()[0]
        names = []
        for row in re.findall(r"^\| [\d-]+ \| `(\w+)` \| ([\w ]+) \|", section, flags=re.M):
            names += [f"{row[0]}_{e}" for e in row[1].split()]
        documented[task] = tuple(names)
    assert documented == {name: cls.state_names for name, cls in rmbench.TASKS.items()}


# ------------------------------------------------------------------------- datasets
def test_datasets_record_the_state(dataset):
    """observation.environment_state: declared with the task's names, with statistics, and
    row t equal to the env's vector at step t of the recorded episode replayed from its seed."""
    from rmbench.data import layout as L
    from rmbench.data.check import check_dataset
    from rmbench.data.reader import Dataset

    check_dataset(dataset)
    ds = Dataset(dataset)
    cls = get_task(ds.task)
    feature = ds.features[L.ENV_STATE]
    assert feature == {"dtype": "float32", "shape": [len(cls.state_names)],
                       "names": list(cls.state_names)}
    assert list(ds.features).index(L.ENV_STATE) == list(ds.features).index(L.STATE) + 1
    assert ds.state_names == list(cls.state_names)
    stats = json.loads((dataset / L.STATS).read_text())[L.ENV_STATE]
    assert len(stats["mean"]) == len(cls.state_names)
    ep = ds.episode(0, cameras=[])
    assert ep.environment_state.shape == (len(ep), len(cls.state_names))
    assert ep.environment_state.dtype == np.float32
    env = rmbench.make(ds.task, render=False)
    env.reset(seed=ep.seed)
    for t, action in enumerate(ep.action):
        assert np.array_equal(env.unwrapped.task.environment_state().astype(np.float32),
                              ep.environment_state[t]), t
        env.step(action.astype(np.float64))
    env.close()


def _strip_environment_state(root: Path) -> None:
    """Turn a dataset into one collected before observation.environment_state existed."""
    import pyarrow.parquet as pq

    from rmbench.data import layout as L

    for path in [*(root / "data").rglob("*.parquet"), *(root / L.EPISODES_DIR).rglob("*.parquet")]:
        table = pq.read_table(path)
        keep = [c for c in table.column_names if c != L.ENV_STATE
                and not c.startswith(f"stats/{L.ENV_STATE}/")]
        pq.write_table(table.select(keep), path, compression="snappy")
    for name in (L.INFO, L.STATS):
        meta = json.loads((root / name).read_text())
        (meta["features"] if name == L.INFO else meta).pop(L.ENV_STATE)
        (root / name).write_text(json.dumps(meta, indent=2) + "\n")


def test_datasets_without_the_state_stay_readable_and_extend_without_it(tmp_path):
    from rmbench.data import collect
    from rmbench.data import layout as L
    from rmbench.data.check import check_dataset
    from rmbench.data.reader import Dataset
    from tests.conftest import small_collection

    out = tmp_path / "old"
    collect(small_collection(out, episodes=1, cameras=("head",)))
    _strip_environment_state(out)
    check_dataset(out)
    ds = Dataset(out)
    assert ds.state_names is None and ds.episode(0, cameras=[]).environment_state is None
    collect(small_collection(out, episodes=2, cameras=("head",)))  # resumes, as it was
    check_dataset(out)
    ds = Dataset(out)
    assert ds.num_episodes == 2 and L.ENV_STATE not in ds.features
    assert ds.episode(1, cameras=[]).environment_state is None
