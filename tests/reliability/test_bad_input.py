"""Reliability suite, part 2: a table-driven sweep of bad input over every command.

Each row is one command line of `riskmap` or `adversary`, built from small fixture files, and the
input it breaks. Every row must end the same way (docs/guide/command-line.md, "Bad input"):
exit status 2, exactly one line on stderr (after argparse's usage block, for malformed flags) that
names the offending flag or path and says what to do, no traceback, and no partial output: an
`--out` that did not exist does not exist afterwards, one that existed keeps its listing (names,
sizes, mtimes).

Commands with a progress bar run with --quiet (as scripts run them). The rows run in process
(`riskmap.cli.main`, `adversary.cli.main`); a few go through the installed entry points too.

FOUND (findings this sweep made, each fixed in the library; one line each):
- sidecar with "kind": null said "a None checkpoint"; another kind was named by its tag only, the
  guard loader said "kind=None" with no fix: read_sidecar names both kinds and the command that
  makes the right one; the guard loads through it (infra/checkpoint.py, guard/predictor.py).
- truncated, empty or PNG .safetensors: SafetensorError traceback (drive, evaluate, tune, train
  --init-checkpoint, guard evaluate, attack): load_tensors, one line naming the file (checkpoint.py).
- NaN/inf checkpoint weights accepted: tracebacks mid-run (drive, evaluate, tune, figures plans,
  guard evaluate), a segfault in train-selector, attack exit 0 with error records: refused on load.
- damaged checkpoint sidecar: JSONDecodeError traceback (guard) or no fix in the message.
- NaN/inf in dataset shards (states, lanes) named no file and surfaced only when drawn, after --out
  existed; train-traffic skipped such windows silently: check_packed refuses them (scene_io.py).
- NaN lanelet points in a CommonRoad map: shapely warnings on stderr, no file named (commonroad.py).
- evaluate --commonroad MISSING named the flag --from-commonroad (collect_commonroad.py).
- train --lr <= 0 / NaN and --device tpu: tracebacks; --goal-variance inf trained (exit 0);
  train-baseline --lr -1 traceback (training/config.py); --backbone-weights PNG traceback (model.py).
- --goal-variance NaN (drive, evaluate, figures plans): traceback; negative: flag not named;
  check-planner --seconds NaN traceback, negative ran (exit 0): positive_float (infra/cli.py).
- tune-goal-variance --candidates NaN / negative: traceback / flag not named; --groups on simulated
  data ended "its groups are " (evaluation/cli.py, data/groups.py).
- guard collect: unknown --seen-envs/--unseen-envs left --out (even episodes); empty --seen-envs
  and --episode-s -1 ran (exit 0), NaN traceback: GuardCollectConfig checks (guard/dataset.py).
- guard train / evaluate: bad --data left --out/.lock; truncated, empty, NaN or keyless job files:
  tracebacks; --lr -0.01 traceback; unknown --splits listed none (guard/dataset.py, train.py, config.py).
- stress-test: a PNG config was a UnicodeDecodeError traceback; an empty one "missing key 'name'";
  YAML, unknown-key and unknown-attack messages said nothing to do (campaign/config.py,
  infra/config_mapping.py, attacks/registry.py).
- report: damaged campaign.json: traceback; a damaged record: report built from a stale index
  (exit 0); figures/ made before any check (report/page.py).
- search: a bad --planner left --out (run.json, .lock); --episode-s -1 / NaN: tracebacks
  (search/run.py); search-report on a damaged run.json: traceback (search/cli.py).
- train-traffic / train-selector: bad --data or --traffic-model left --out/.lock; --lr,
  --kl-weight, --free-bits, --max-windows-per-episode unchecked (crash/config.py, train_*.py).
- scenes: unknown --env or --t0 below 2 s looped forever (every episode "skipped"); NaN --t0 and
  --first-episode -1: tracebacks (crash/run.py, crash/scenes.py).
- attack: truncated, PNG or NaN scene files ran (exit 0, error records in --out); negative
  --iterations / --panels ran (crash/run.py, crash/scenes.py, crash/cli.py).
- guard-data: a damaged attack record: traceback; a missing scene left --out/.lock (guard_data.py).
- every command: a path under a regular file said "File exists"; `guard`/`figures` subcommands
  were not named; a mismatch message could span lines (infra/cli.py, infra/checkpoint.py).
- evaluate --planners "," said "give each SPEC once"; --episode-s inf was not refused
  (evaluation/cli.py, evaluation/evaluate.py).
- a sidecar without its grid, irl (or irl.horizon), sampler, maps or bc section: KeyError traceback
  (drive, evaluate): each planner's loader names the sections it reads (require_sections), one
  line naming the checkpoint and its sidecar (infra/checkpoint.py, planner/*).
- validating before creating --out must not lose "a second writer stops at once": the lock is
  probed, without creating anything, before inputs are read (infra/rundir.py refuse_if_locked).
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np
import pytest

from adversary.cli import main as adversary_main
from riskmap.cli import main as riskmap_main

REPO = Path(__file__).resolve().parents[2]
CHECKPOINTS = REPO / "checkpoints"
COMMONROAD = REPO / "tests" / "fixtures" / "commonroad"
GOOD_XML = COMMONROAD / "USA_US101-4_1_T-1.xml"     # has demonstrators
PASSWD = Path("/etc/passwd")
PROC_OUT = "/proc/riskmap-no-such-dir/out"          # the system refuses to create it, root or not
IS_ROOT = hasattr(os, "geteuid") and os.geteuid() == 0

# The error line says what to do: an imperative or a requirement.
FIX_WORDS = re.compile(
    r"\b(pass|use|choose|run|rerun|give|collect|train|delete|check|install|record|make|drop|add|"
    r"remove|repair|re-collect|wait|leave|keep|point|resume|must|need|needs|fix|write|rename|"
    r"change|replace|free|name)\b", re.IGNORECASE)


# ---------------------------------------------------------------------------------------------
# Fixtures: small files made once per module, each bad variant a copy of a good one.


def _truncate(path: Path, keep: float = 0.5) -> None:
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * keep)])


def _png_bytes() -> bytes:
    import cv2

    ok, buffer = cv2.imencode(".png", np.full((8, 8, 3), 127, np.uint8))
    assert ok
    return buffer.tobytes()


def _copy_checkpoint(source: Path, target: Path) -> Path:
    target.parent.mkdir(parents=True, exist_ok=True)
    for suffix in (".safetensors", ".json"):
        shutil.copyfile(source.with_suffix(suffix), target.with_suffix(suffix))
    return target


def _poison_weights(path: Path, value: float) -> None:
    from safetensors.torch import load_file, save_file

    state = load_file(str(path.with_suffix(".safetensors")))
    name = next(k for k, v in state.items() if v.is_floating_point() and v.numel() > 1)
    tensor = state[name].clone()
    tensor.view(-1)[0] = value
    state[name] = tensor
    save_file(state, str(path.with_suffix(".safetensors")))


def _copy_dataset(source: Path, target: Path) -> Path:
    shutil.copytree(source, target, ignore=shutil.ignore_patterns(".lock", "cache"))
    return target


# The ways any input file is broken (`Fixtures.spoil`).
SPOILS = ("half", "empty", "png", "passwd")


def _edit_npz(path: Path, edit) -> None:
    """Rewrite the .npz at `path` after `edit(arrays)` has changed its arrays (a dict) in place."""
    with np.load(path) as data:
        arrays = {k: data[k] for k in data.files}
    edit(arrays)
    with open(path, "wb") as f:
        np.savez_compressed(f, **arrays)


def _edit_shard(dataset: Path, edit) -> Path:
    _edit_npz(min((dataset / "shards").glob("*.npz")), edit)
    return dataset


def _poison_state(value: float):
    def edit(arrays):
        ego, now = int(arrays["ego_index"][0]), int(arrays["current_index"][0])
        assert arrays["valid"][0, ego, now]
        arrays["states"][0, ego, now, 0] = value
    return edit


def _poison_lane(arrays):
    arrays["lane_centre"][0, 0] = np.nan


def _poison_first_track(arrays):
    """NaN in the first value of a scene's first float array of rank 3 or more (its tracks)."""
    key = next(k for k in arrays if arrays[k].dtype.kind == "f" and arrays[k].ndim >= 3)
    arrays[key].reshape(-1)[0] = np.nan


class Fixtures:
    """Every input a row needs, made on first use under `root`."""

    def __init__(self, root: Path):
        self.root = root

    def dir(self, name: str) -> Path:
        path = self.root / name
        path.mkdir(parents=True, exist_ok=True)
        return path

    def spoil(self, path: Path, how: str) -> None:
        """Break the file at `path` one of the SPOILS ways every reader must survive: cut in half,
        emptied, or replaced by a PNG or by /etc/passwd (readable text, not the format)."""
        if how == "half":
            _truncate(path)
        elif how == "empty":
            path.write_bytes(b"")
        elif how == "png":
            path.write_bytes(self.png.read_bytes())
        elif how == "passwd":
            path.write_bytes(PASSWD.read_bytes())
        else:
            raise KeyError(how)

    def spoil_part(self, variant: str, **parts: Path) -> bool:
        """For a variant named HOW_PART (half_manifest, png_shard, passwd_sidecar, ...): spoil the
        file `parts[PART]` the HOW way and say True; False for any other variant."""
        how, _, part = variant.partition("_")
        if how not in SPOILS or part not in parts:
            return False
        self.spoil(parts[part], how)
        return True

    # -- plain files ---------------------------------------------------------------------------
    @cached_property
    def png(self) -> Path:
        path = self.root / "picture.png"
        path.write_bytes(_png_bytes())
        return path

    @cached_property
    def empty(self) -> Path:
        path = self.root / "empty.txt"
        path.write_bytes(b"")
        return path

    @cached_property
    def file(self) -> Path:
        """A regular file, so that `file/out` cannot be made."""
        path = self.root / "regular_file"
        path.write_text("not a directory\n")
        return path

    # -- riskmap datasets ----------------------------------------------------------------------
    @cached_property
    def dataset(self) -> Path:
        """Two short intersection episodes (the intersection checkpoints' raster)."""
        from riskmap.data.collect import CollectConfig, collect

        out = self.root / "dataset"
        collect(CollectConfig("intersection-v0", episodes=2, seed=11), out, progress=False)
        return out

    def dataset_variant(self, name: str) -> Path:
        target = self.root / "datasets" / name
        if target.exists():
            return target
        data = _copy_dataset(self.dataset, target)
        manifest = data / "manifest.json"
        if self.spoil_part(name, manifest=manifest, shard=min((data / "shards").glob("*.npz"))):
            return data
        if name == "old_version":
            content = json.loads(manifest.read_text())
            content["config"]["format_version"] = 1
            manifest.write_text(json.dumps(content))
        elif name == "no_index":
            (data / "index.json").unlink()
        elif name == "nan_scene":
            _edit_shard(data, _poison_state(np.nan))
        elif name == "inf_scene":
            _edit_shard(data, _poison_state(np.inf))
        elif name == "nan_map":
            _edit_shard(data, _poison_lane)
        else:
            raise KeyError(name)
        return data

    # -- CommonRoad files ----------------------------------------------------------------------
    def xml(self, name: str) -> Path:
        path = self.root / "xml" / f"{name}.xml"
        if path.exists():
            return path
        path.parent.mkdir(parents=True, exist_ok=True)
        text = GOOD_XML.read_text()
        if name in SPOILS:
            path.write_text(text)
            self.spoil(path, name)
        elif name == "nan_map":
            # every lanelet bound's first x is NaN: the map itself is broken
            path.write_text(re.sub(r"(<leftBound>\s*<point>\s*<x>)[^<]*(</x>)", r"\1nan\2", text))
        else:
            raise KeyError(name)
        return path

    # -- checkpoints ---------------------------------------------------------------------------
    def checkpoint(self, source: str, variant: str = "good") -> Path:
        """A copy of checkpoints/`source` (path without suffix), broken as `variant` says."""
        target = self.root / "ck" / source.replace("/", "_") / variant / "best"
        if target.with_suffix(".json").exists():
            return target
        _copy_checkpoint(CHECKPOINTS / source, target)
        weights, sidecar = target.with_suffix(".safetensors"), target.with_suffix(".json")
        if variant == "good" or self.spoil_part(variant, weights=weights, sidecar=sidecar):
            return target
        if variant == "no_kind":
            content = json.loads(sidecar.read_text())
            del content["kind"]
            sidecar.write_text(json.dumps(content))
        elif variant == "null_kind":
            content = json.loads(sidecar.read_text())
            content["kind"] = None
            sidecar.write_text(json.dumps(content))
        elif variant == "newer_format":           # written by a later toolkit
            content = json.loads(sidecar.read_text())
            content["format_version"] = 99
            sidecar.write_text(json.dumps(content))
        elif variant == "time_gap_ahead_yes":     # a planning setting of the wrong type
            content = json.loads(sidecar.read_text())
            content.setdefault("planning", {})["time_gap"] = {"weight": 20.0, "ahead_only": "yes"}
            sidecar.write_text(json.dumps(content))
        elif variant.startswith("without_"):     # without_model, without_irl.horizon: a part left out
            content = json.loads(sidecar.read_text())
            *parents, name = variant.removeprefix("without_").split(".")
            section = content
            for key in parents:
                section = section[key]
            del section[name]
            sidecar.write_text(json.dumps(content))
        elif variant == "nan_weights":
            _poison_weights(target, float("nan"))
        elif variant == "inf_weights":
            _poison_weights(target, float("inf"))
        else:
            raise KeyError(variant)
        return target

    # -- guard datasets (synthetic windows in the layout of `riskmap guard collect`) ----------
    def guard_data(self, variant: str = "good") -> Path:
        from riskmap.guard.features import EDGE_DIM, NODE_DIM, OBSERVED

        root = self.root / "guard" / variant
        if root.exists():
            return root
        jobs = root / "jobs"
        jobs.mkdir(parents=True)
        rng = np.random.default_rng(0)
        for split in ("train", "val", "seen", "unseen"):
            n = 16
            arrays = {"node_u": rng.normal(size=(n, NODE_DIM)).astype(np.float32),
                      "node_i": rng.normal(size=(n, NODE_DIM)).astype(np.float32),
                      "edge": rng.normal(size=(n, OBSERVED, EDGE_DIM)).astype(np.float32),
                      "mask": np.ones((n, OBSERVED), bool),
                      "ttc_s": np.where(np.arange(n) % 2 == 1, 0.5, np.inf).astype(np.float32),
                      "neighbour": np.ones(n, np.int32), "last_step": np.arange(n, dtype=np.int32),
                      "frame_node_u": rng.normal(size=(n, NODE_DIM)).astype(np.float32),
                      "frame_node_i": rng.normal(size=(n, NODE_DIM)).astype(np.float32),
                      "frame_edge": rng.normal(size=(n, OBSERVED, EDGE_DIM)).astype(np.float32),
                      "frame_mask": np.ones((n, OBSERVED), bool),
                      "frame": (np.arange(n) // 2).astype(np.int32), "frames": np.array([n // 2], np.int32)}
            np.savez_compressed(jobs / f"{split}_highway-v0_idm_s0_e0000_nat.npz", **arrays)
        first = jobs / "train_highway-v0_idm_s0_e0000_nat.npz"
        if self.spoil_part(variant, job=first):
            return root
        if variant == "old_format":          # an older version's file: a fixed label, no time to contact
            _edit_npz(first, lambda a: a.update(label=(a.pop("ttc_s") < 1).astype(np.int8),
                                                edge=a["edge"][..., :1]))
        elif variant == "narrow_edges":      # d_s only: an edge dimension this version does not read
            _edit_npz(first, lambda a: a.update(edge=np.ascontiguousarray(a["edge"][..., :1])))
        elif variant == "nan_frame":
            _edit_npz(first, lambda a: a["frame_edge"].__setitem__((0, 0, 0), np.nan))
        elif variant == "nan_job":
            _edit_npz(first, lambda a: a["edge"].__setitem__((0, 0, 0), np.nan))
        elif variant == "wrong_keys":
            np.savez_compressed(first, something=np.zeros(3))
        elif variant != "good":
            raise KeyError(variant)
        return root

    # -- campaign configs and directories ------------------------------------------------------
    GOOD_CAMPAIGN = ("name: bad-input\nseed: 0\nplanners: [cv]\n"
                     "scenarios:\n  - {env: highway-v0, seed: 0, episodes: 1}\n"
                     "attacks:\n  - {name: natural}\nbudget: {episode_s: 1.0}\n")

    def campaign_yaml(self, variant: str = "good") -> Path:
        path = self.root / "campaigns" / f"{variant}.yaml"
        if path.exists():
            return path
        path.parent.mkdir(parents=True, exist_ok=True)
        good = self.GOOD_CAMPAIGN
        if variant in SPOILS:
            path.write_text(good)
            self.spoil(path, variant)
            return path
        texts = {
            "good": good,
            "unknown_key": good + "colour: blue\n",
            "unknown_attack_key": good.replace("{name: natural}", "{name: natural, speed: 3}"),
            "unknown_param": good.replace("{name: natural}",
                                          "{name: aggressive_neighbour, params: {nosuch: 1}}"),
            "unknown_attack": good.replace("{name: natural}", "{name: nosuch_attack}"),
            "planner_nosuch": good.replace("[cv]", "[nosuch]"),
            "planner_missing": good.replace("[cv]", "['riskmap:/nonexistent/ck']"),
            "planner_py_key": good.replace(
                "[cv]", "['py:riskmap.planner.baselines:ConstantVelocityPlanner?nosuch=1']"),
            "planner_name_twice": good.replace(
                "[cv]", "['py:riskmap.planner.baselines:ConstantVelocityPlanner?name=ego', "
                        "'py:tests.broken_planners:Broken?name=ego']"),
            "planner_guard_ck": good.replace(
                "[cv]", f"['riskmap:{self.checkpoint('guard_tgat')}']"),
            "episodes_negative": good.replace("episodes: 1", "episodes: -1"),
            "env_nope": good.replace("highway-v0", "nope-v0"),
            "episode_s_negative": good.replace("episode_s: 1.0", "episode_s: -1.0"),
            "episode_s_nan": good.replace("episode_s: 1.0", "episode_s: .nan"),
            "not_a_mapping": "- just\n- a list\n",
            "crash_model_missing": good.replace(
                "{name: natural}", "{name: crash, params: {traffic_model: /nonexistent/traffic}}"),
        }
        path.write_text(texts[variant])
        return path

    @cached_property
    def campaign_dir(self) -> Path:
        """A finished one-job campaign (cv, natural, 1 s)."""
        from adversary.campaign.config import load_campaign
        from adversary.campaign.run import RunOptions, run_campaign

        out = self.root / "campaign_run"
        run_campaign(load_campaign(self.campaign_yaml()), out, RunOptions(progress=False))
        return out

    def campaign_variant(self, variant: str) -> Path:
        target = self.root / "campaign_variants" / variant
        if target.exists():
            return target
        shutil.copytree(self.campaign_dir, target, ignore=shutil.ignore_patterns(".lock"))
        if variant != "good" and not self.spoil_part(variant, meta=target / "campaign.json",
                                                     record=min((target / "records").rglob("*.json"))):
            raise KeyError(variant)
        return target

    # -- search runs ---------------------------------------------------------------------------
    def search_variant(self, variant: str) -> Path:
        root = self.root / "search" / variant
        if root.exists():
            return root
        root.mkdir(parents=True)
        if variant == "half_run":
            (root / "run.json").write_text('{"config": {"planner": "cv", "templ')
        elif variant == "passwd_run":
            (root / "run.json").write_bytes(PASSWD.read_bytes())
        elif variant == "no_config":
            (root / "run.json").write_text('{"something": 1}')
        elif variant != "empty":
            raise KeyError(variant)
        return root

    # -- CRASH inputs --------------------------------------------------------------------------
    @cached_property
    def scenes(self) -> Path:
        """One held-out highway attack scene (`adversary scenes`)."""
        from adversary.crash.scene_sweep import EnvSweep, record_scenes

        out = self.root / "scenes"
        record_scenes(EnvSweep("highway-v0", 0), 1, out, progress=False)
        return out

    def scenes_variant(self, variant: str) -> Path:
        target = self.root / "scene_variants" / variant
        if target.exists():
            return target
        shutil.copytree(self.scenes, target)
        scene = min(target.glob("scene_*.npz"))
        if variant == "good" or self.spoil_part(variant, index=target / "index.json", scene=scene):
            return target
        if variant == "nan_scene":
            _edit_npz(scene, _poison_first_track)
        else:
            raise KeyError(variant)
        return target

    def attack_run(self, variant: str = "good") -> Path:
        """An `adversary attack --out` directory whose one record had no candidate (nothing to
        drive again), or a broken variant of it."""
        root = self.root / "attack_runs" / variant
        if root.exists():
            return root
        (root / "attacks").mkdir(parents=True)
        (root / "run.json").write_text(json.dumps(
            {"planner": "replay", "scenes": str(self.root / "no_scenes"), "seed": 0,
             "config": {"selector": "distance"}}))
        (root / "attacks" / "scene_00000.json").write_text(json.dumps(
            {"name": "scene_00000", "status": "no_candidate", "collision": False}))
        if variant == "good" or self.spoil_part(variant, run=root / "run.json",
                                                record=root / "attacks" / "scene_00000.json"):
            return root
        if variant == "no_records":
            (root / "attacks" / "scene_00000.json").unlink()
        elif variant == "ok_record_no_scene":
            (root / "attacks" / "scene_00000.json").write_text(json.dumps(
                {"name": "scene_00000", "status": "ok", "collision": False,
                 "scene": {"env_id": "highway-v0", "scene_seed": 0, "episode": 0}}))
        else:
            raise KeyError(variant)
        return root


@pytest.fixture(scope="module")
def fx(tmp_path_factory) -> Fixtures:
    return Fixtures(tmp_path_factory.mktemp("bad_input_fixtures"))


# ---------------------------------------------------------------------------------------------
# The table.


@dataclass(frozen=True)
class Row:
    id: str
    argv: Callable            # (fx, t) -> [prog, *args]; t: a fresh folder for this row
    names: Callable           # (fx, t) -> tuple of strings; the error line holds one of them
    out: Callable | None = lambda fx, t: t / "out"    # the --out that must stay as it was
    usage: bool = False       # an argparse usage error is the expected answer (malformed flag)
    watch: Callable | None = None   # (fx, t) -> more paths whose listing must not change
    root_skip: bool = False   # permissions do not bite for root
    marks: tuple = field(default_factory=tuple)


def S(*strings):
    """names: fixed strings, or callables of (fx, t) giving one."""
    return lambda fx, t: tuple(str(s(fx, t)) if callable(s) else str(s) for s in strings)


OUT = "out"          # placeholder in argv: the row's fresh --out path (t / "out")


def _argv(*parts):
    """argv from parts: strings, OUT, or callables (fx, t) -> str | Path."""
    def build(fx, t):
        return [str(t / "out") if p is OUT else str(p(fx, t)) if callable(p) else str(p)
                for p in parts]
    return build


def ds(name=None):
    return (lambda fx, t: fx.dataset) if name is None else (lambda fx, t: fx.dataset_variant(name))


def ck(source, variant="good"):
    return lambda fx, t: fx.checkpoint(source, variant)


def xml(name):
    return lambda fx, t: fx.xml(name)


def under_file(fx, t):
    return fx.file / "out"


def existing_file(fx, t):
    path = t / "out_file"
    if not path.exists():
        path.write_text("keep me\n")
    return path


def existing_dir(fx, t):
    """An --out that exists (empty): its listing must not change (not even a lock file)."""
    path = t / "existing_out"
    path.mkdir(exist_ok=True)
    return path


def missing(name="missing"):
    return lambda fx, t: t / name


def locked_parent(fx, t):
    parent = t / "locked"
    parent.mkdir(exist_ok=True)
    parent.chmod(0o000)
    return parent / "out"


def readonly_out(fx, t):
    out = t / "readonly"
    out.mkdir(exist_ok=True)
    out.chmod(0o555)
    return out


PNG = lambda fx, t: fx.png
EMPTY = lambda fx, t: fx.empty
FILE = lambda fx, t: fx.file
RM = "checkpoints/riskmap_intersection"     # the riskmap checkpoint of the intersection data
RM_SRC = "riskmap_intersection"
RM_ST_SRC = "riskmap_st_intersection"       # the space-time planner of the same data
GUARD_SRC = "guard_tgat"
TRAFFIC_SRC = "crash_traffic_intersection"
BC_SRC = "bc_cnn_intersection"
CV_PY = "py:riskmap.planner.baselines:ConstantVelocityPlanner"    # a py: SPEC that loads at once

COLLECT = ("riskmap", "collect")
TRAIN = ("riskmap", "train")
BASELINE = ("riskmap", "train-baseline", "cnn")
DRIVE = ("riskmap", "drive")
EVAL = ("riskmap", "evaluate")
TUNE = ("riskmap", "tune-goal-variance")
FIG_SCENES = ("riskmap", "figures", "scenes")
FIG_PLANS = ("riskmap", "figures", "plans")
G_COLLECT = ("riskmap", "guard", "collect")
G_TRAIN = ("riskmap", "guard", "train")
G_EVAL = ("riskmap", "guard", "evaluate")
STRESS = ("adversary", "stress-test")
REPORT = ("adversary", "report")
SEARCH = ("adversary", "search")
SEARCH_REPORT = ("adversary", "search-report")
SELECTOR = ("adversary", "train-selector")
SCENES = ("adversary", "scenes")
ATTACK = ("adversary", "attack")
GUARD_DATA = ("adversary", "guard-data")
TRAFFIC = ("adversary", "train-traffic")
HARDEN = ("adversary", "harden")
EXPORT = ("adversary", "export")
ADV_EVAL = ("adversary", "evaluate")


def R(id, argv, names, **kw):
    return Row(id, argv, names, **kw)


PROC_NAMES = S(PROC_OUT, "/proc/riskmap-no-such-dir")      # the out, or the parent that cannot be made
UNDER_FILE_NAMES = S(under_file, FILE)                     # the out, or the file in its way


ROWS: list[Row] = []


def add(*rows):
    ROWS.extend(rows)


def data_rows(prefix, command, fast):
    """The row maker of a command that reads one --data folder: `row(id, data, names, *extra,
    out_arg=OUT, **kw)` is row `prefix/id`, running COMMAND --data DATA FAST... EXTRA... --out OUT_ARG."""
    def row(id, data, names, *extra, out_arg=OUT, **kw):
        return R(f"{prefix}/{id}", _argv(*command, "--data", data, *fast, *extra, "--out", out_arg),
                 names, **kw)
    return row


# (id, --data, names): the damaged `riskmap collect` datasets every command that trains on one refuses
# before --out exists, naming the file.
DAMAGED_DATA = (
    ("data-missing", missing("nodata"), S(missing("nodata"))),
    ("manifest-truncated", ds("half_manifest"), S("manifest.json")),
    ("shard-truncated", ds("half_shard"), S("episode_000000.npz")),
    ("scene-nan", ds("nan_scene"), S("episode_000000.npz")),
)


def damaged_checkpoints(source, other=GUARD_SRC):
    """(what, checkpoint): the checkpoints in place of one of `source` that a command loading it
    refuses, naming it: one of another kind (`other`'s), one without a kind, truncated weights,
    NaN weights."""
    return (("guard-kind", ck(other)), ("no-kind", ck(source, "no_kind")),
            ("truncated", ck(source, "half_weights")), ("nan-weights", ck(source, "nan_weights")))


# riskmap collect ---------------------------------------------------------------------------------
C_SIM = ("--episodes", "1", "--quiet")
add(
    R("collect/env-unknown", _argv(*COLLECT, "--env", "nope-v0", *C_SIM, "--out", OUT), S("nope-v0")),
    R("collect/episodes-zero", _argv(*COLLECT, "--env", "highway-v0", "--episodes", "0", "--out", OUT),
      S("--episodes"), usage=True),
    R("collect/episodes-negative", _argv(*COLLECT, "--env", "highway-v0", "--episodes", "-3", "--out", OUT),
      S("--episodes"), usage=True),
    R("collect/workers-zero", _argv(*COLLECT, "--env", "highway-v0", *C_SIM, "--workers", "0", "--out", OUT),
      S("--workers"), usage=True),
    R("collect/human-unknown", _argv(*COLLECT, "--env", "highway-v0", *C_SIM, "--human", "robot", "--out", OUT),
      S("--human"), usage=True),
    R("collect/both-sources", _argv(*COLLECT, "--env", "highway-v0", *C_SIM, "--from-commonroad",
                                    lambda fx, t: GOOD_XML, "--out", OUT), S("--from-commonroad")),
    R("collect/cr-missing", _argv(*COLLECT, "--from-commonroad", missing("none.xml"), "--out", OUT),
      S(missing("none.xml"))),
    R("collect/cr-empty", _argv(*COLLECT, "--from-commonroad", xml("empty"), "--out", OUT), S(xml("empty"))),
    R("collect/cr-truncated", _argv(*COLLECT, "--from-commonroad", xml("half"), "--out", OUT), S(xml("half"))),
    R("collect/cr-png", _argv(*COLLECT, "--from-commonroad", xml("png"), "--out", OUT), S(xml("png"))),
    R("collect/cr-png-suffix", _argv(*COLLECT, "--from-commonroad", PNG, "--out", OUT), S(PNG)),
    R("collect/cr-passwd", _argv(*COLLECT, "--from-commonroad", PASSWD, "--out", OUT), S(PASSWD)),
    R("collect/cr-dir-without-xml", _argv(*COLLECT, "--from-commonroad", lambda fx, t: fx.dir("empty_dir"),
                                          "--out", OUT), S(lambda fx, t: fx.dir("empty_dir"))),
    R("collect/cr-nan-map", _argv(*COLLECT, "--from-commonroad", xml("nan_map"), "--out", OUT),
      S(xml("nan_map"))),
    R("collect/out-under-file", _argv(*COLLECT, "--env", "highway-v0", *C_SIM, "--out", under_file),
      UNDER_FILE_NAMES, out=under_file),
    R("collect/out-proc", _argv(*COLLECT, "--env", "highway-v0", *C_SIM, "--out", PROC_OUT),
      PROC_NAMES, out=lambda fx, t: Path(PROC_OUT)),
    R("collect/out-is-a-file", _argv(*COLLECT, "--env", "highway-v0", *C_SIM, "--out", existing_file),
      S(existing_file), out=existing_file),
    R("collect/out-parent-000", _argv(*COLLECT, "--env", "highway-v0", *C_SIM, "--out", locked_parent),
      S(locked_parent), out=locked_parent, root_skip=True),
    R("collect/resume-truncated-manifest",
      _argv(*COLLECT, "--env", "intersection-v0", "--episodes", "2", "--seed", "11", "--resume", "--quiet",
            "--out", ds("half_manifest")),
      S(lambda fx, t: fx.dataset_variant("half_manifest")), out=ds("half_manifest")),
)

# riskmap train ------------------------------------------------------------------------------------
T_FAST = ("--resolution", "25", "--epochs", "1", "--batch-size", "2", "--max-windows", "2", "--quiet")
train_row = data_rows("train", TRAIN, T_FAST)


add(
    *(train_row(*case) for case in DAMAGED_DATA),
    train_row("data-empty-dir", lambda fx, t: fx.dir("empty_dir"), S(lambda fx, t: fx.dir("empty_dir"))),
    train_row("data-passwd", PASSWD, S(PASSWD)),
    train_row("data-png", PNG, S(PNG)),
    train_row("data-is-guard-dataset", lambda fx, t: fx.guard_data(), S(lambda fx, t: fx.guard_data())),
    train_row("manifest-empty", ds("empty_manifest"), S("manifest.json")),
    train_row("manifest-passwd", ds("passwd_manifest"), S("manifest.json")),
    train_row("format-version", ds("old_version"), S(ds("old_version"))),
    train_row("index-missing", ds("no_index"), S("index.json")),
    train_row("shard-empty", ds("empty_shard"), S("episode_000000.npz")),
    train_row("shard-png", ds("png_shard"), S("episode_000000.npz")),
    train_row("scene-inf", ds("inf_scene"), S("episode_000000.npz")),
    train_row("map-nan", ds("nan_map"), S("episode_000000.npz")),
    train_row("resolution-zero", ds(), S("--resolution"), "--resolution", "0", usage=True),
    train_row("epochs-negative", ds(), S("--epochs"), "--epochs", "-1", usage=True),
    train_row("lr-negative", ds(), S("--lr"), "--lr", "-0.1"),
    train_row("raster-px-tiny", ds(), S("--raster-px"), "--raster-px", "8"),
    train_row("raster-px-zero", ds(), S("--raster-px"), "--raster-px", "0", usage=True),
    train_row("lr-nan", ds(), S("--lr"), "--lr", "nan"),
    train_row("goal-variance-negative", ds(), S("--goal-variance"), "--goal-variance", "-5"),
    train_row("goal-variance-inf", ds(), S("--goal-variance"), "--goal-variance", "inf"),
    train_row("sigma-zero", ds(), S("--sigma-x"), "--sigma-x", "0"),
    train_row("device-unknown", ds(), S("--device"), "--device", "tpu"),
    train_row("init-guard-checkpoint", ds(), S(ck(GUARD_SRC)), "--init-checkpoint", ck(GUARD_SRC)),
    train_row("init-truncated", ds(), S(ck(RM_SRC, "half_weights")), "--init-checkpoint",
              ck(RM_SRC, "half_weights")),
    train_row("init-nan-weights", ds(), S(ck(RM_SRC, "nan_weights")), "--init-checkpoint",
              ck(RM_SRC, "nan_weights")),
    train_row("init-missing", ds(), S(missing("noinit")), "--init-checkpoint", missing("noinit")),
    train_row("backbone-png", ds(), S(PNG), "--backbone-weights", PNG),
    train_row("backbone-missing", ds(), S(missing("nobackbone.pth")), "--backbone-weights",
              missing("nobackbone.pth")),
    train_row("spacetime-steps-five", ds(), S("--steps"), "--planner", "spacetime", "--steps", "5"),
    train_row("spacetime-max-forward-zero", ds(), S("--max-forward"), "--planner", "spacetime",
              "--max-forward", "0"),
    train_row("spacetime-max-across-nine", ds(), S("--max-across"), "--planner", "spacetime",
              "--max-across", "9"),
    train_row("spacetime-timing-head", ds(), S("--timing-head"), "--planner", "spacetime",
              "--timing-head"),
    train_row("planner-unknown", ds(), S("--planner"), "--planner", "temporal", usage=True),
    train_row("out-under-file", ds(), UNDER_FILE_NAMES, out_arg=under_file, out=under_file),
    train_row("out-is-a-file", ds(), S(existing_file), out_arg=existing_file, out=existing_file),
    train_row("out-parent-000", ds(), S(locked_parent), out_arg=locked_parent, out=locked_parent,
              root_skip=True),
)

# riskmap train-baseline --------------------------------------------------------------------------
B_FAST = ("--epochs", "1", "--batch-size", "2", "--max-windows", "2", "--quiet")
baseline_row = data_rows("train-baseline", BASELINE, B_FAST)


add(
    *(baseline_row(*case) for case in DAMAGED_DATA),
    baseline_row("history-frames-zero", ds(), S("--history-frames"), "--history-frames", "0", usage=True),
    baseline_row("lr-negative", ds(), S("--lr"), "--lr", "-1"),
    baseline_row("predict-s-negative", ds(), S("--predict-s"), "--predict-s", "-2"),
    baseline_row("out-under-file", ds(), UNDER_FILE_NAMES, out_arg=under_file, out=under_file),
    R("train-baseline/kind-unknown", _argv("riskmap", "train-baseline", "transformer", "--data", ds(),
                                           "--out", OUT), S("kind"), usage=True),
)

# riskmap drive ------------------------------------------------------------------------------------
D_ARGS = ("--env", "intersection-v0", "--episodes", "1", "--quiet")


def drive_row(id, planner_args, names, *extra, **kw):
    return R(f"drive/{id}", _argv(*DRIVE, *planner_args, *D_ARGS, *extra, "--out", kw.pop("out_arg", OUT)),
             names, **kw)


add(
    drive_row("planner-nosuch", ("--planner", "nosuch"), S("nosuch")),
    drive_row("planner-riskmap-missing", ("--planner", "riskmap:/missing"), S("/missing")),
    drive_row("planner-idm-with-arg", ("--planner", "idm:fast"), S("idm:fast")),
    drive_row("planner-guard-of-nosuch", ("--planner", "guard:nosuch"), S("nosuch")),
    drive_row("planner-cnn-of-riskmap-ck", ("--planner", lambda fx, t: f"cnn:{fx.checkpoint(RM_SRC)}"),
              S(ck(RM_SRC))),
    drive_row("planner-riskmap-of-bc-ck", ("--planner", lambda fx, t: f"riskmap:{fx.checkpoint(BC_SRC)}"),
              S(ck(BC_SRC))),
    drive_row("planner-py-unknown-key", ("--planner", "py:riskmap.planner.baselines:ConstantVelocityPlanner?nosuch=1"),
              S("nosuch")),
    drive_row("planner-py-no-module", ("--planner", "py:no_such_module_xyz:Planner"), S("no_such_module_xyz")),
    drive_row("planner-py-no-factory", ("--planner", "py:riskmap.planner.baselines:NoSuchPlanner"),
              S("NoSuchPlanner")),
    drive_row("planner-cr-no-module", ("--planner", "cr:no_such_module_xyz:Planner"), S("no_such_module_xyz")),
    drive_row("planner-cr-no-plan", ("--planner", "cr:tests.broken_planners:not_a_planner"),
              S("cr:tests.broken_planners:not_a_planner", "plan(sc, pp")),
    drive_row("planner-cr-bad-predict",
              ("--planner", "cr:riskmap.planner.baselines:ConstantVelocityPlanner?predict=psychic"),
              S("predict='psychic'")),
    drive_row("checkpoint-and-planner", ("--checkpoint", ck(RM_SRC), "--planner", "idm"), S("--checkpoint")),
    drive_row("ck-guard-kind", ("--checkpoint", ck(GUARD_SRC)), S(ck(GUARD_SRC))),
    drive_row("ck-traffic-kind", ("--checkpoint", ck(TRAFFIC_SRC)), S(ck(TRAFFIC_SRC))),
    drive_row("ck-no-kind", ("--checkpoint", ck(RM_SRC, "no_kind")), S(ck(RM_SRC, "no_kind"))),
    drive_row("ck-null-kind", ("--checkpoint", ck(RM_SRC, "null_kind")), S(ck(RM_SRC, "null_kind"))),
    drive_row("ck-newer-format", ("--checkpoint", ck(RM_SRC, "newer_format")), S("version 99, newer")),
    drive_row("ck-truncated-weights", ("--checkpoint", ck(RM_SRC, "half_weights")), S(ck(RM_SRC, "half_weights"))),
    drive_row("ck-empty-weights", ("--checkpoint", ck(RM_SRC, "empty_weights")), S(ck(RM_SRC, "empty_weights"))),
    drive_row("ck-png-weights", ("--checkpoint", ck(RM_SRC, "png_weights")), S(ck(RM_SRC, "png_weights"))),
    drive_row("ck-truncated-sidecar", ("--checkpoint", ck(RM_SRC, "half_sidecar")), S(ck(RM_SRC, "half_sidecar"))),
    drive_row("ck-empty-sidecar", ("--checkpoint", ck(RM_SRC, "empty_sidecar")), S(ck(RM_SRC, "empty_sidecar"))),
    drive_row("ck-passwd-sidecar", ("--checkpoint", ck(RM_SRC, "passwd_sidecar")),
              S(ck(RM_SRC, "passwd_sidecar"))),
    drive_row("ck-passwd", ("--checkpoint", PASSWD), S(PASSWD)),
    drive_row("ck-png", ("--checkpoint", PNG), S(PNG)),
    drive_row("ck-nan-weights", ("--checkpoint", ck(RM_SRC, "nan_weights")), S(ck(RM_SRC, "nan_weights"))),
    drive_row("ck-inf-weights", ("--checkpoint", ck(RM_SRC, "inf_weights")), S(ck(RM_SRC, "inf_weights"))),
    drive_row("bc-nan-weights", ("--planner", lambda fx, t: f"cnn:{fx.checkpoint(BC_SRC, 'nan_weights')}"),
              S(ck(BC_SRC, "nan_weights"))),
    drive_row("ck-without-model", ("--checkpoint", ck(RM_SRC, "without_model")), S(ck(RM_SRC, "without_model"))),
    drive_row("ck-without-grid", ("--checkpoint", ck(RM_SRC, "without_grid")), S(ck(RM_SRC, "without_grid"))),
    drive_row("ck-without-irl-horizon", ("--checkpoint", ck(RM_SRC, "without_irl.horizon")),
              S(ck(RM_SRC, "without_irl.horizon"))),
    drive_row("st-without-spacetime", ("--checkpoint", ck(RM_ST_SRC, "without_spacetime")),
              S(ck(RM_ST_SRC, "without_spacetime"))),
    drive_row("st-without-maps", ("--checkpoint", ck(RM_ST_SRC, "without_maps")), S(ck(RM_ST_SRC, "without_maps"))),
    drive_row("st-time-gap-ahead-yes", ("--checkpoint", ck(RM_ST_SRC, "time_gap_ahead_yes")),
              S("ahead_only 'yes' must be true or false")),
    drive_row("bc-without-bc", ("--planner", lambda fx, t: f"cnn:{fx.checkpoint(BC_SRC, 'without_bc')}"),
              S(ck(BC_SRC, "without_bc"))),
    drive_row("frames-ck-without-model", ("--checkpoint", ck(RM_SRC, "without_model")),
              S(ck(RM_SRC, "without_model")), "--frames"),
    R("drive/frames-cv-env-unknown", _argv(*DRIVE, "--planner", "cv", "--frames", "--env", "nope-v0",
                                           "--episodes", "1", "--out", OUT), S("nope-v0")),
    drive_row("frames-py-unknown-key", ("--planner", "py:riskmap.planner.baselines:ConstantVelocityPlanner?nosuch=1"),
              S("nosuch"), "--frames"),
    R("drive/env-unknown", _argv(*DRIVE, "--planner", "idm", "--env", "nope-v0", "--episodes", "1",
                                 "--out", OUT), S("nope-v0")),
    R("drive/episodes-zero", _argv(*DRIVE, "--planner", "idm", "--env", "highway-v0", "--episodes", "0",
                                   "--out", OUT), S("--episodes"), usage=True),
    drive_row("goal-variance-negative", ("--checkpoint", ck(RM_SRC)), S("--goal-variance"),
              "--goal-variance", "-1", usage=True),
    drive_row("goal-variance-nan", ("--checkpoint", ck(RM_SRC)), S("--goal-variance"), "--goal-variance", "nan",
              usage=True),
    drive_row("out-under-file", ("--planner", "idm"), UNDER_FILE_NAMES, out_arg=under_file, out=under_file),
    drive_row("out-proc", ("--planner", "idm"), PROC_NAMES, out_arg=PROC_OUT, out=lambda fx, t: Path(PROC_OUT)),
    drive_row("out-readonly", ("--planner", "idm"), S(readonly_out), out_arg=readonly_out, out=readonly_out,
              root_skip=True),
)

# riskmap check-planner (no --out: nothing may be written at all) -------------------------------
CHECK = ("riskmap", "check-planner")
add(
    R("check-planner/spec-nosuch", _argv(*CHECK, "nosuch", "--envs", "highway-v0"), S("nosuch"), out=None),
    R("check-planner/spec-py-unknown-key", _argv(*CHECK, "py:riskmap.planner.baselines:ConstantVelocityPlanner"
                                                   "?nosuch=1", "--envs", "highway-v0"), S("nosuch"), out=None),
    R("check-planner/ck-nan-weights", _argv(*CHECK, lambda fx, t: f"riskmap:{fx.checkpoint(RM_SRC, 'nan_weights')}",
                                            "--envs", "highway-v0"), S(ck(RM_SRC, "nan_weights")), out=None),
    R("check-planner/env-unknown", _argv(*CHECK, "cv", "--envs", "nope-v0"), S("nope-v0"), out=None),
    R("check-planner/spec-py-name-parent", _argv(*CHECK, f"{CV_PY}?name=..", "--envs", "highway-v0"),
      S("name='..'"), out=None),
    R("check-planner/commonroad-missing", _argv(*CHECK, "cv", "--commonroad", missing("norec")),
      S(missing("norec")), out=None),
    R("check-planner/commonroad-png", _argv(*CHECK, "cv", "--commonroad", lambda fx, t: fx.png),
      S(lambda fx, t: fx.png), out=None),
    R("check-planner/seconds-negative", _argv(*CHECK, "cv", "--envs", "highway-v0", "--seconds", "-1"),
      S("--seconds"), out=None, usage=True),
    R("check-planner/seconds-nan", _argv(*CHECK, "cv", "--envs", "highway-v0", "--seconds", "nan"),
      S("--seconds"), out=None, usage=True),
)

# riskmap evaluate ---------------------------------------------------------------------------------
E_SIM = ("--env", "highway-v0", "--episodes", "1", "--quiet")
add(
    R("evaluate/cr-passwd", _argv(*EVAL, "--planners", "cv", "--commonroad", PASSWD, "--out", OUT), S(PASSWD)),
    R("evaluate/cr-missing", _argv(*EVAL, "--planners", "cv", "--commonroad", missing("x.xml"), "--out", OUT),
      S(missing("x.xml"))),
    R("evaluate/cr-truncated", _argv(*EVAL, "--planners", "cv", "--commonroad", xml("half"), "--out", OUT),
      S(xml("half"))),
    R("evaluate/cr-empty", _argv(*EVAL, "--planners", "cv", "--commonroad", xml("empty"), "--out", OUT),
      S(xml("empty"))),
    R("evaluate/cr-png", _argv(*EVAL, "--planners", "cv", "--commonroad", xml("png"), "--out", OUT),
      S(xml("png"))),
    R("evaluate/cr-max-episodes-zero", _argv(*EVAL, "--planners", "cv", "--commonroad", lambda fx, t: GOOD_XML,
                                             "--max-episodes", "0", "--out", OUT), S("--max-episodes"), usage=True),
    R("evaluate/cr-episodes-instead", _argv(*EVAL, "--planners", "cv", "--commonroad", lambda fx, t: GOOD_XML,
                                            "--episodes", "2", "--out", OUT), S("--max-episodes")),
    R("evaluate/cr-planner-nosuch", _argv(*EVAL, "--planners", "cv,nosuch", "--commonroad",
                                          lambda fx, t: GOOD_XML, "--out", OUT), S("nosuch")),
    R("evaluate/cr-goal-variance-nan", _argv(*EVAL, "--planners", lambda fx, t: f"riskmap:{fx.checkpoint(RM_SRC)}",
                                             "--commonroad", lambda fx, t: GOOD_XML, "--goal-variance", "nan",
                                             "--out", OUT), S("--goal-variance"), usage=True),
    R("evaluate/planner-nosuch", _argv(*EVAL, "--planners", "idm,nosuch", *E_SIM, "--out", OUT), S("nosuch")),
    R("evaluate/planner-riskmap-missing", _argv(*EVAL, "--planners", "riskmap:/missing", *E_SIM, "--out", OUT),
      S("/missing")),
    R("evaluate/planner-guard-ck", _argv(*EVAL, "--planners", lambda fx, t: f"riskmap:{fx.checkpoint(GUARD_SRC)}",
                                         *E_SIM, "--out", OUT), S(ck(GUARD_SRC))),
    R("evaluate/planner-nan-weights", _argv(*EVAL, "--planners",
                                            lambda fx, t: f"riskmap:{fx.checkpoint(RM_SRC, 'nan_weights')}",
                                            *E_SIM, "--out", OUT), S(ck(RM_SRC, "nan_weights"))),
    R("evaluate/planner-without-model", _argv(*EVAL, "--planners",
                                              lambda fx, t: f"cv,riskmap:{fx.checkpoint(RM_SRC, 'without_model')}",
                                              *E_SIM, "--out", OUT), S(ck(RM_SRC, "without_model"))),
    R("evaluate/planners-repeated", _argv(*EVAL, "--planners", "cv,cv", *E_SIM, "--out", OUT), S("--planners")),
    R("evaluate/planner-name-path", _argv(*EVAL, "--planners", f"cv,{CV_PY}?name=runs/a", *E_SIM, "--out", OUT),
      S("runs/a")),
    R("evaluate/planner-name-empty", _argv(*EVAL, "--planners", f"{CV_PY}?headway_s=2&name=", *E_SIM,
                                           "--out", OUT), S("name=")),
    R("evaluate/planner-name-twice", _argv(*EVAL, "--planners", f"{CV_PY}?name=ego,py:tests.broken_planners:Broken"
                                           "?name=ego", *E_SIM, "--out", OUT), S("name=ego")),
    R("evaluate/planners-empty", _argv(*EVAL, "--planners", ",", *E_SIM, "--out", OUT), S("--planners")),
    R("evaluate/env-unknown", _argv(*EVAL, "--planners", "cv", "--env", "nope-v0", "--episodes", "1",
                                    "--out", OUT), S("nope-v0")),
    R("evaluate/episodes-zero", _argv(*EVAL, "--planners", "cv", "--env", "highway-v0", "--episodes", "0",
                                      "--out", OUT), S("--episodes"), usage=True),
    R("evaluate/episode-s-negative", _argv(*EVAL, "--planners", "cv", *E_SIM, "--episode-s", "-4",
                                           "--out", OUT), S("--episode-s")),
    R("evaluate/episode-s-inf", _argv(*EVAL, "--planners", "cv", *E_SIM, "--episode-s", "inf", "--out", OUT),
      S("--episode-s")),
    R("evaluate/episode-s-nan", _argv(*EVAL, "--planners", "cv", *E_SIM, "--episode-s", "nan", "--out", OUT),
      S("--episode-s")),
    R("evaluate/replan-hz-3", _argv(*EVAL, "--planners", "cv", *E_SIM, "--replan-hz", "3", "--out", OUT),
      S("--replan-hz")),
    R("evaluate/cr-replan-hz-4", _argv(*EVAL, "--planners", "cv", "--commonroad", lambda fx, t: GOOD_XML,
                                       "--replan-hz", "4", "--out", OUT), S("--replan-hz")),
    R("evaluate/replay-reactive", _argv(*EVAL, "--planners", "replay", *E_SIM, "--mode", "reactive",
                                        "--out", OUT), S("replay")),
    R("evaluate/out-under-file", _argv(*EVAL, "--planners", "cv", *E_SIM, "--out", under_file),
      UNDER_FILE_NAMES, out=under_file),
)

# riskmap tune-goal-variance (writes the checkpoint's sidecar: that must stay unchanged) ----------


def tune_row(id, checkpoint, data, names, *extra, **kw):
    return R(f"tune-goal-variance/{id}", _argv(*TUNE, "--checkpoint", checkpoint, "--data", data,
                                               "--limit", "2", *extra),
             names, out=None, watch=lambda fx, t: [fx.checkpoint(RM_SRC).parent], **kw)


add(
    *(tune_row(f"ck-{what}", checkpoint, ds(), S(checkpoint))
      for what, checkpoint in damaged_checkpoints(RM_SRC)),
    tune_row("data-missing", ck(RM_SRC), missing("nodata"), S(missing("nodata"))),
    tune_row("data-scene-nan", ck(RM_SRC), ds("nan_scene"), S("episode_000000.npz")),
    tune_row("candidates-text", ck(RM_SRC), ds(), S("--candidates"), "--candidates", "five,two"),
    tune_row("candidates-negative", ck(RM_SRC), ds(), S("--candidates"), "--candidates", "5,-1"),
    tune_row("candidates-nan", ck(RM_SRC), ds(), S("--candidates"), "--candidates", "nan"),
    tune_row("candidates-empty", ck(RM_SRC), ds(), S("--candidates"), "--candidates", ""),
    tune_row("limit-zero", ck(RM_SRC), ds(), S("--limit"), "--limit", "0", usage=True),
    tune_row("groups-on-simulated-data", ck(RM_SRC), ds(), S("group 7"), "--groups", "7"),
)

# riskmap figures scenes / plans -----------------------------------------------------------------
add(
    R("figures-scenes/data-missing", _argv(*FIG_SCENES, "--data", missing("nodata"), "--out", OUT),
      S(missing("nodata"))),
    R("figures-scenes/shard-truncated", _argv(*FIG_SCENES, "--data", ds("half_shard"), "--out", OUT),
      S("episode_000000.npz")),
    R("figures-scenes/scene-nan", _argv(*FIG_SCENES, "--data", ds("nan_scene"), "--out", OUT),
      S("episode_000000.npz")),
    R("figures-scenes/map-nan", _argv(*FIG_SCENES, "--data", ds("nan_map"), "--out", OUT),
      S("episode_000000.npz")),
    R("figures-scenes/count-zero", _argv(*FIG_SCENES, "--data", ds(), "--count", "0", "--out", OUT),
      S("--count"), usage=True),
    R("figures-scenes/out-under-file", _argv(*FIG_SCENES, "--data", ds(), "--count", "1", "--out", under_file),
      UNDER_FILE_NAMES, out=under_file),
    R("figures-scenes/out-proc", _argv(*FIG_SCENES, "--data", ds(), "--count", "1", "--out", PROC_OUT),
      PROC_NAMES, out=lambda fx, t: Path(PROC_OUT)),
    R("figures-plans/ck-guard-kind", _argv(*FIG_PLANS, "--checkpoint", ck(GUARD_SRC), "--data", ds(),
                                           "--count", "1", "--out", OUT), S(ck(GUARD_SRC))),
    R("figures-plans/ck-nan-weights", _argv(*FIG_PLANS, "--checkpoint", ck(RM_SRC, "nan_weights"),
                                            "--data", ds(), "--count", "1", "--out", OUT),
      S(ck(RM_SRC, "nan_weights"))),
    R("figures-plans/ck-missing", _argv(*FIG_PLANS, "--checkpoint", missing("nock"), "--data", ds(),
                                        "--count", "1", "--out", OUT), S(missing("nock"))),
    R("figures-plans/raster-mismatch", _argv(*FIG_PLANS, "--checkpoint", ck("riskmap_highway"), "--data", ds(),
                                             "--count", "1", "--out", OUT), S(ds())),
    R("figures-plans/data-scene-nan", _argv(*FIG_PLANS, "--checkpoint", ck(RM_SRC), "--data", ds("nan_scene"),
                                            "--count", "1", "--out", OUT), S("episode_000000.npz")),
    R("figures-plans/goal-variance-negative", _argv(*FIG_PLANS, "--checkpoint", ck(RM_SRC), "--data", ds(),
                                                    "--count", "1", "--goal-variance", "-3", "--out", OUT),
      S("--goal-variance"), usage=True),
    R("figures-plans/count-zero", _argv(*FIG_PLANS, "--checkpoint", ck(RM_SRC), "--data", ds(),
                                        "--count", "0", "--out", OUT), S("--count"), usage=True),
)

# riskmap guard collect / train / evaluate -------------------------------------------------------
GC_FAST = ("--train-episodes", "1", "--seen-episodes", "1", "--unseen-episodes", "1", "--episode-s", "1",
           "--quiet")
add(
    R("guard-collect/seen-env-unknown", _argv(*G_COLLECT, "--seen-envs", "nope-v0", *GC_FAST, "--out", OUT),
      S("nope-v0")),
    R("guard-collect/unseen-env-unknown", _argv(*G_COLLECT, "--unseen-envs", "nope-v0", *GC_FAST, "--out", OUT),
      S("nope-v0")),
    R("guard-collect/seen-envs-empty", _argv(*G_COLLECT, "--seen-envs", ",", *GC_FAST, "--out", OUT),
      S("--seen-envs")),
    R("guard-collect/train-episodes-zero", _argv(*G_COLLECT, "--train-episodes", "0", "--out", OUT),
      S("--train-episodes"), usage=True),
    R("guard-collect/episode-s-negative", _argv(*G_COLLECT, *GC_FAST, "--episode-s", "-1", "--out", OUT),
      S("--episode-s")),
    R("guard-collect/episode-s-nan", _argv(*G_COLLECT, *GC_FAST, "--episode-s", "nan", "--out", OUT),
      S("--episode-s")),
    R("guard-collect/planner-every-zero", _argv(*G_COLLECT, "--planner-every", "0", "--out", OUT),
      S("--planner-every"), usage=True),
    R("guard-collect/out-under-file", _argv(*G_COLLECT, *GC_FAST, "--out", under_file), UNDER_FILE_NAMES,
      out=under_file),
    R("guard-collect/out-proc", _argv(*G_COLLECT, *GC_FAST, "--out", PROC_OUT), PROC_NAMES,
      out=lambda fx, t: Path(PROC_OUT)),
)


gtrain_row = data_rows("guard-train", G_TRAIN, ("--epochs", "1", "--quiet"))


add(
    gtrain_row("data-missing", missing("nodata"), S(missing("nodata"))),
    gtrain_row("data-empty-dir", lambda fx, t: fx.dir("empty_dir"), S(lambda fx, t: fx.dir("empty_dir"))),
    gtrain_row("data-is-riskmap-dataset", ds(), S(ds())),
    gtrain_row("data-passwd", PASSWD, S(PASSWD)),
    gtrain_row("job-truncated", lambda fx, t: fx.guard_data("half_job"), S("train_highway-v0_idm")),
    gtrain_row("job-empty", lambda fx, t: fx.guard_data("empty_job"), S("train_highway-v0_idm")),
    gtrain_row("job-nan", lambda fx, t: fx.guard_data("nan_job"), S("train_highway-v0_idm")),
    gtrain_row("job-wrong-keys", lambda fx, t: fx.guard_data("wrong_keys"), S("train_highway-v0_idm")),
    gtrain_row("job-old-format", lambda fx, t: fx.guard_data("old_format"), S("train_highway-v0_idm")),
    gtrain_row("job-narrow-edges", lambda fx, t: fx.guard_data("narrow_edges"), S("train_highway-v0_idm")),
    gtrain_row("job-nan-frame", lambda fx, t: fx.guard_data("nan_frame"), S("train_highway-v0_idm")),
    gtrain_row("horizon-s-zero", lambda fx, t: fx.guard_data(), S("--horizon-s"), "--horizon-s", "0"),
    gtrain_row("horizon-s-beyond-data", lambda fx, t: fx.guard_data(), S("--horizon-s"), "--horizon-s", "4"),
    gtrain_row("alert-ratio-one", lambda fx, t: fx.guard_data(), S("--alert-ratio"), "--alert-ratio", "1"),
    gtrain_row("ttc-weight-negative", lambda fx, t: fx.guard_data(), S("--ttc-weight"), "--ttc-weight", "-1"),
    gtrain_row("ttc-weight-nan", lambda fx, t: fx.guard_data(), S("--ttc-weight"), "--ttc-weight", "nan"),
    gtrain_row("epochs-zero", lambda fx, t: fx.guard_data(), S("--epochs"), "--epochs", "0", usage=True),
    gtrain_row("lr-negative", lambda fx, t: fx.guard_data(), S("--lr"), "--lr", "-0.01"),
    gtrain_row("out-under-file", lambda fx, t: fx.guard_data(), UNDER_FILE_NAMES, out_arg=under_file,
               out=under_file),
)


def geval_row(id, checkpoint, data, names, *extra, **kw):
    out = kw.pop("out_arg", None)
    return R(f"guard-evaluate/{id}", _argv(*G_EVAL, "--checkpoint", checkpoint, "--data", data, *extra,
                                           *(("--out", out) if out is not None else ())),
             names, out=kw.pop("out", lambda fx, t: t / "metrics.json"), **kw)


GD = lambda fx, t: fx.guard_data()
add(
    geval_row("ck-riskmap-kind", ck(RM_SRC), GD, S(ck(RM_SRC))),
    geval_row("ck-no-kind", ck(GUARD_SRC, "no_kind"), GD, S(ck(GUARD_SRC, "no_kind"))),
    geval_row("ck-truncated-weights", ck(GUARD_SRC, "half_weights"), GD, S(ck(GUARD_SRC, "half_weights"))),
    geval_row("ck-truncated-sidecar", ck(GUARD_SRC, "half_sidecar"), GD, S(ck(GUARD_SRC, "half_sidecar"))),
    geval_row("ck-nan-weights", ck(GUARD_SRC, "nan_weights"), GD, S(ck(GUARD_SRC, "nan_weights"))),
    geval_row("ck-missing", missing("nock"), GD, S(missing("nock"))),
    geval_row("data-missing", ck(GUARD_SRC), missing("nodata"), S(missing("nodata"))),
    geval_row("data-is-riskmap-dataset", ck(GUARD_SRC), ds(), S(ds())),
    geval_row("job-nan", ck(GUARD_SRC), lambda fx, t: fx.guard_data("nan_job"), S("train_highway-v0_idm"),
              "--splits", "train"),
    geval_row("split-unknown", ck(GUARD_SRC), GD, S("nosuch"), "--splits", "seen,nosuch"),
    geval_row("job-old-format", ck(GUARD_SRC), lambda fx, t: fx.guard_data("old_format"),
              S("train_highway-v0_idm"), "--splits", "train"),
    geval_row("job-truncated", ck(GUARD_SRC), lambda fx, t: fx.guard_data("half_job"),
              S("train_highway-v0_idm"), "--splits", "train"),
    geval_row("out-under-file", ck(GUARD_SRC), GD, UNDER_FILE_NAMES, out_arg=under_file, out=under_file),
    geval_row("out-proc", ck(GUARD_SRC), GD, PROC_NAMES,
              out_arg="/proc/riskmap-no-such-dir/metrics.json",
              out=lambda fx, t: Path("/proc/riskmap-no-such-dir/metrics.json")),
)

# adversary stress-test / report -----------------------------------------------------------------


def stress_row(id, variant, names, *extra, **kw):
    return R(f"stress-test/{id}", _argv(*STRESS, "--config", lambda fx, t: fx.campaign_yaml(variant),
                                        "--quiet", *extra, "--out", kw.pop("out_arg", OUT)), names, **kw)


CFG = lambda variant: (lambda fx, t: fx.campaign_yaml(variant))
add(
    R("stress-test/config-missing", _argv(*STRESS, "--config", missing("c.yaml"), "--out", OUT),
      S(missing("c.yaml"))),
    R("stress-test/config-is-dir", _argv(*STRESS, "--config", lambda fx, t: fx.dir("empty_dir"), "--out", OUT),
      S(lambda fx, t: fx.dir("empty_dir"))),
    stress_row("config-empty", "empty", S(CFG("empty"))),
    stress_row("config-truncated", "half", S(CFG("half"))),
    stress_row("config-passwd", "passwd", S(CFG("passwd"))),
    stress_row("config-png", "png", S(CFG("png"))),
    stress_row("config-list", "not_a_mapping", S(CFG("not_a_mapping"))),
    stress_row("unknown-key", "unknown_key", S("colour")),
    stress_row("unknown-attack-key", "unknown_attack_key", S("speed")),
    stress_row("unknown-attack-param", "unknown_param", S("nosuch")),
    stress_row("unknown-attack", "unknown_attack", S("nosuch_attack")),
    stress_row("planner-nosuch", "planner_nosuch", S("nosuch")),
    stress_row("planner-ck-missing", "planner_missing", S("/nonexistent/ck")),
    stress_row("planner-guard-ck", "planner_guard_ck", S(ck(GUARD_SRC))),
    stress_row("planner-py-unknown-key", "planner_py_key", S("nosuch")),
    stress_row("planner-name-twice", "planner_name_twice", S("name=ego")),
    stress_row("episodes-negative", "episodes_negative", S("episodes")),
    stress_row("env-unknown", "env_nope", S("nope-v0")),
    stress_row("episode-s-negative", "episode_s_negative", S("episode_s")),
    stress_row("episode-s-nan", "episode_s_nan", S("episode_s")),
    stress_row("crash-model-missing", "crash_model_missing", S("/nonexistent/traffic")),
    stress_row("workers-zero", "good", S("--workers"), "--workers", "0"),
    stress_row("max-jobs-zero", "good", S("--max-jobs"), "--max-jobs", "0"),
    stress_row("out-under-file", "good", UNDER_FILE_NAMES, out_arg=under_file, out=under_file),
    stress_row("out-parent-000", "good", S(locked_parent), out_arg=locked_parent, out=locked_parent,
               root_skip=True),
    stress_row("out-proc", "good", PROC_NAMES, out_arg=PROC_OUT, out=lambda fx, t: Path(PROC_OUT)),
)

CAMPAIGN = lambda variant: (lambda fx, t: fx.campaign_variant(variant))
add(
    R("report/dir-missing", _argv(*REPORT, missing("nocampaign")), S(missing("nocampaign")),
      out=missing("nocampaign")),
    R("report/dir-empty", _argv(*REPORT, lambda fx, t: fx.dir("report_empty")),
      S(lambda fx, t: fx.dir("report_empty")), out=lambda fx, t: fx.dir("report_empty")),
    R("report/dir-is-file", _argv(*REPORT, FILE), S(FILE), out=FILE),
    R("report/meta-truncated", _argv(*REPORT, CAMPAIGN("half_meta")), S("campaign.json"),
      out=CAMPAIGN("half_meta")),
    R("report/meta-passwd", _argv(*REPORT, CAMPAIGN("passwd_meta")), S("campaign.json"),
      out=CAMPAIGN("passwd_meta")),
    R("report/record-truncated", _argv(*REPORT, CAMPAIGN("half_record")), S(CAMPAIGN("half_record")),
      out=CAMPAIGN("half_record")),
    R("report/out-under-file", _argv(*REPORT, CAMPAIGN("good"), "--out", under_file), UNDER_FILE_NAMES,
      out=under_file, watch=lambda fx, t: [fx.campaign_variant("good")]),
)

# adversary search / search-report ---------------------------------------------------------------
S_FAST = ("--template", "cut_in", "--pop", "2", "--gen", "1", "--episode-s", "1", "--quiet")
add(
    R("search/planner-nosuch", _argv(*SEARCH, "--planner", "nosuch", *S_FAST, "--out", OUT), S("nosuch")),
    R("search/planner-ck-missing", _argv(*SEARCH, "--planner", "riskmap:/missing", *S_FAST, "--out", OUT),
      S("/missing")),
    R("search/planner-guard-ck", _argv(*SEARCH, "--planner", lambda fx, t: f"riskmap:{fx.checkpoint(GUARD_SRC)}",
                                       *S_FAST, "--out", OUT), S(ck(GUARD_SRC))),
    R("search/template-unknown", _argv(*SEARCH, "--planner", "cv", "--template", "nosuch", "--out", OUT),
      S("--template"), usage=True),
    R("search/pop-zero", _argv(*SEARCH, "--planner", "cv", "--template", "cut_in", "--pop", "0", "--out", OUT),
      S("--pop"), usage=True),
    R("search/pop-one", _argv(*SEARCH, "--planner", "cv", *S_FAST, "--pop", "1", "--out", OUT), S("--pop")),
    R("search/episode-s-negative", _argv(*SEARCH, "--planner", "cv", *S_FAST, "--episode-s", "-1", "--out", OUT),
      S("--episode-s")),
    R("search/episode-s-nan", _argv(*SEARCH, "--planner", "cv", *S_FAST, "--episode-s", "nan", "--out", OUT),
      S("--episode-s")),
    R("search/out-under-file", _argv(*SEARCH, "--planner", "cv", *S_FAST, "--out", under_file), UNDER_FILE_NAMES,
      out=under_file),
    R("search-report/out-missing", _argv(*SEARCH_REPORT, "--out", missing("nosearch")),
      S(missing("nosearch")), out=missing("nosearch")),
    R("search-report/out-empty", _argv(*SEARCH_REPORT, "--out", lambda fx, t: fx.search_variant("empty")),
      S(lambda fx, t: fx.search_variant("empty")), out=lambda fx, t: fx.search_variant("empty")),
    R("search-report/run-truncated", _argv(*SEARCH_REPORT, "--out", lambda fx, t: fx.search_variant("half_run")),
      S("run.json"), out=lambda fx, t: fx.search_variant("half_run")),
    R("search-report/run-passwd", _argv(*SEARCH_REPORT, "--out", lambda fx, t: fx.search_variant("passwd_run")),
      S("run.json"), out=lambda fx, t: fx.search_variant("passwd_run")),
    R("search-report/run-no-config", _argv(*SEARCH_REPORT, "--out", lambda fx, t: fx.search_variant("no_config")),
      S("run.json"), out=lambda fx, t: fx.search_variant("no_config")),
)

# adversary train-selector / train-traffic ------------------------------------------------------
SEL_FAST = ("--max-scenes", "2", "--label-iterations", "1", "--epochs", "1", "--quiet")


def selector_row(id, traffic, data, names, *extra, **kw):
    return R(f"train-selector/{id}", _argv(*SELECTOR, "--traffic-model", traffic, "--data", data, *SEL_FAST,
                                           *extra, "--out", kw.pop("out_arg", OUT)), names, **kw)


add(
    selector_row("traffic-missing", missing("notraffic"), ds(), S(missing("notraffic"))),
    *(selector_row(f"traffic-{what}", traffic, ds(), S(traffic))
      for what, traffic in damaged_checkpoints(TRAFFIC_SRC)),
    selector_row("traffic-bc-kind", ck(BC_SRC), ds(), S(ck(BC_SRC))),
    selector_row("data-missing", ck(TRAFFIC_SRC), missing("nodata"), S(missing("nodata"))),
    selector_row("data-scene-nan", ck(TRAFFIC_SRC), ds("nan_scene"), S("episode_000000.npz")),
    selector_row("data-manifest-truncated", ck(TRAFFIC_SRC), ds("half_manifest"), S("manifest.json")),
    selector_row("epochs-zero", ck(TRAFFIC_SRC), ds(), S("--epochs"), "--epochs", "0", usage=True),
    selector_row("out-under-file", ck(TRAFFIC_SRC), ds(), UNDER_FILE_NAMES, out_arg=under_file, out=under_file),
)

TR_FAST = ("--epochs", "1", "--quiet")
traffic_row = data_rows("train-traffic", TRAFFIC, TR_FAST)


add(
    *(traffic_row(*case) for case in DAMAGED_DATA),
    traffic_row("data-png", PNG, S(PNG)),
    traffic_row("map-nan", ds("nan_map"), S("episode_000000.npz")),
    traffic_row("epochs-zero", ds(), S("--epochs"), "--epochs", "0", usage=True),
    traffic_row("lr-negative", ds(), S("--lr"), "--lr", "-1"),
    traffic_row("kl-weight-nan", ds(), S("--kl-weight"), "--kl-weight", "nan"),
    traffic_row("free-bits-negative", ds(), S("--free-bits"), "--free-bits", "-2"),
    traffic_row("max-windows-negative", ds(), S("--max-windows-per-episode"), "--max-windows-per-episode", "-1"),
    traffic_row("out-under-file", ds(), UNDER_FILE_NAMES, out_arg=under_file, out=under_file),
)

# adversary scenes / attack / guard-data --------------------------------------------------------
add(
    R("scenes/env-unknown", _argv(*SCENES, "--env", "nope-v0", "--seed", "0", "--count", "1", "--out", OUT),
      S("nope-v0")),
    R("scenes/count-zero", _argv(*SCENES, "--env", "highway-v0", "--seed", "0", "--count", "0", "--out", OUT),
      S("--count"), usage=True),
    R("scenes/t0-short", _argv(*SCENES, "--env", "highway-v0", "--seed", "0", "--count", "1", "--t0", "1",
                               "--out", OUT), S("t0")),
    R("scenes/t0-nan", _argv(*SCENES, "--env", "highway-v0", "--seed", "0", "--count", "1", "--t0", "nan",
                             "--out", OUT), S("t0")),
    R("scenes/seed-negative", _argv(*SCENES, "--env", "highway-v0", "--seed", "-1", "--count", "1",
                                    "--out", OUT), S("--seed")),
    R("scenes/first-episode-negative", _argv(*SCENES, "--env", "highway-v0", "--seed", "0", "--count", "1",
                                             "--first-episode", "-1", "--out", OUT), S("--first-episode")),
    R("scenes/static-agents-negative", _argv(*SCENES, "--env", "highway-v0", "--seed", "0", "--count", "1",
                                             "--static-agents", "-1", "--out", OUT), S("--static-agents"),
      usage=True),
    R("scenes/static-agents-roundabout", _argv(*SCENES, "--env", "roundabout-v0", "--seed", "0", "--count", "1",
                                               "--static-agents", "2", "--out", OUT), S("--static-agents")),
    R("scenes/out-under-file", _argv(*SCENES, "--env", "highway-v0", "--seed", "0", "--count", "1", "--quiet",
                                     "--out", under_file), UNDER_FILE_NAMES, out=under_file),
    R("scenes/out-proc", _argv(*SCENES, "--env", "highway-v0", "--seed", "0", "--count", "1", "--quiet",
                               "--out", PROC_OUT), PROC_NAMES, out=lambda fx, t: Path(PROC_OUT)),
)

SC = lambda variant="good": (lambda fx, t: fx.scenes_variant(variant))
A_FAST = ("--count", "1", "--iterations", "1", "--quiet")


def attack_row(id, scenes, names, *extra, planner="replay", selector="distance", **kw):
    return R(f"attack/{id}", _argv(*ATTACK, "--planner", planner, "--scenes", scenes, "--selector", selector,
                                   *A_FAST, *extra, "--out", kw.pop("out_arg", OUT)), names, **kw)


add(
    attack_row("scenes-missing", missing("noscenes"), S(missing("noscenes"))),
    attack_row("scenes-empty-dir", lambda fx, t: fx.dir("empty_dir"), S(lambda fx, t: fx.dir("empty_dir"))),
    attack_row("index-truncated", SC("half_index"), S(SC("half_index"))),
    attack_row("scene-truncated", SC("half_scene"), S("scene_00000.npz")),
    attack_row("scene-png", SC("png_scene"), S("scene_00000.npz")),
    attack_row("scene-nan", SC("nan_scene"), S("scene_00000.npz")),
    attack_row("count-too-many", SC(), S("--count"), "--count", "5"),
    attack_row("planner-nosuch", SC(), S("nosuch"), planner="nosuch"),
    attack_row("planner-ck-missing", SC(), S("/missing"), planner="riskmap:/missing"),
    attack_row("traffic-guard-kind", SC(), S(ck(GUARD_SRC)), "--traffic-model", ck(GUARD_SRC)),
    attack_row("traffic-truncated", SC(), S(ck("crash_traffic_highway", "half_weights")),
               "--traffic-model", ck("crash_traffic_highway", "half_weights")),
    attack_row("traffic-nan-weights", SC(), S(ck("crash_traffic_highway", "nan_weights")),
               "--traffic-model", ck("crash_traffic_highway", "nan_weights")),
    attack_row("selector-model-missing", SC(), S(missing("nosel")), "--selector-model", missing("nosel"),
               selector="crash"),
    attack_row("selector-model-is-traffic", SC(), S(lambda fx, t: fx.checkpoint("crash_traffic_highway").parent),
               "--selector-model", lambda fx, t: fx.checkpoint("crash_traffic_highway").parent, selector="crash"),
    attack_row("iterations-negative", SC(), S("--iterations"), "--iterations", "-1", usage=True),
    attack_row("panels-negative", SC(), S("--panels"), "--panels", "-1", usage=True),
    attack_row("replan-hz-3", SC(), S("--replan-hz"), "--replan-hz", "3"),
    attack_row("scenes-is-a-dataset", ds(), S(ds())),
    attack_row("out-under-file", SC(), UNDER_FILE_NAMES, out_arg=under_file, out=under_file),
)


def adv_eval_row(id, scenes, names, *extra, planners="replay", **kw):
    return R(f"adversary-evaluate/{id}", _argv(*ADV_EVAL, "--scenes", scenes, "--planners", planners, "--quiet",
                                               *extra, "--out", kw.pop("out_arg", OUT)), names, **kw)


add(
    adv_eval_row("scenes-missing", missing("noscenes"), S(missing("noscenes"))),
    adv_eval_row("scenes-no-index", lambda fx, t: fx.dir("empty_dir"), S(lambda fx, t: fx.dir("empty_dir"))),
    adv_eval_row("index-truncated", SC("half_index"), S(SC("half_index"))),
    adv_eval_row("scene-truncated", SC("half_scene"), S("scene_00000.npz")),
    adv_eval_row("scene-nan", SC("nan_scene"), S("scene_00000.npz")),
    adv_eval_row("count-too-many", SC(), S("--count"), "--count", "5"),
    adv_eval_row("count-zero", SC(), S("--count"), "--count", "0", usage=True),
    adv_eval_row("planner-nosuch", SC(), S("nosuch"), planners="replay,nosuch"),
    adv_eval_row("planners-empty", SC(), S("--planners"), planners=","),
    adv_eval_row("out-under-file", SC(), UNDER_FILE_NAMES, out_arg=under_file, out=under_file),
)

# adversary harden: the intersection checkpoint with its kind of data, highway attack scenes
def harden_row(id, names, *, checkpoint=RM, natural=None, scenes=None, extra=(), **kw):
    return R(f"harden/{id}", _argv(*HARDEN, "--checkpoint", checkpoint, "--natural", natural or ds(),
                                   "--scenes", scenes or SC(), "--count", "1", "--quiet", *extra,
                                   "--out", kw.pop("out_arg", OUT)), names, **kw)


add(
    harden_row("checkpoint-missing", S(missing("nock")), checkpoint=missing("nock")),
    harden_row("checkpoint-guard-kind", S(ck(GUARD_SRC)), checkpoint=ck(GUARD_SRC)),
    harden_row("natural-missing", S(missing("nodata")), natural=missing("nodata")),
    harden_row("natural-other-raster", S(ds()), checkpoint="checkpoints/riskmap_highway"),
    harden_row("natural-share-one", S("--natural-share"), extra=("--natural-share", "1")),
    harden_row("search-share-one", S("--search-share"), extra=("--search-share", "1")),
    harden_row("natural-env-unknown", S("nope-v0"), extra=("--natural-env", "nope-v0")),
    harden_row("scenes-missing", S(missing("noscenes")), scenes=missing("noscenes")),
    harden_row("count-too-many", S("--count"), extra=("--count", "5")),
    harden_row("rounds-zero", S("--rounds"), extra=("--rounds", "0"), usage=True),
    harden_row("keep-unknown", S("--keep"), extra=("--keep", "first"), usage=True),
    harden_row("out-under-file", UNDER_FILE_NAMES, out_arg=under_file, out=under_file),
)

AR = lambda variant="good": (lambda fx, t: fx.attack_run(variant))


def export_row(id, run, names, *extra, **kw):
    return R(f"export/{id}", _argv(*EXPORT, "--run", run, "--format", kw.pop("format", "commonroad"),
                                   "--quiet", *extra, "--out", kw.pop("out_arg", OUT)), names, **kw)


add(
    export_row("run-missing", missing("norun"), S(missing("norun"))),
    export_row("run-empty-dir", lambda fx, t: fx.dir("empty_dir"), S(lambda fx, t: fx.dir("empty_dir"))),
    export_row("run-truncated", AR("half_run"), S(AR("half_run"))),
    export_row("format-unknown", AR(), S("--format"), format="opendrive", usage=True),
    export_row("run-scenes-missing", AR(), S("no_scenes")),    # its run.json names a missing folder
    export_row("scenes-flag-missing", AR(), S(missing("noscenes")), "--scenes", missing("noscenes")),
    # a campaign directory (found by its store layout): a job it does not have; one natural job only
    export_row("campaign-job-unknown", CAMPAIGN("good"), S("--job nope"), "--job", "nope",
               watch=lambda fx, t: [fx.campaign_variant("good")]),
    export_row("campaign-nothing-exportable", CAMPAIGN("good"), S("can be exported"),
               watch=lambda fx, t: [fx.campaign_variant("good")]),
)


def gdata_row(id, attacks, names, *extra, **kw):
    return R(f"guard-data/{id}", _argv(*GUARD_DATA, "--attacks", attacks, "--quiet", *extra, "--out",
                                       kw.pop("out_arg", OUT)), names, **kw)


add(
    gdata_row("attacks-missing", missing("noattacks"), S(missing("noattacks"))),
    gdata_row("attacks-empty-dir", lambda fx, t: fx.dir("empty_dir"), S(lambda fx, t: fx.dir("empty_dir"))),
    gdata_row("run-truncated", AR("half_run"), S(AR("half_run"))),
    gdata_row("no-records", AR("no_records"), S(AR("no_records"))),
    gdata_row("record-truncated", AR("half_record"), S("scene_00000.json")),
    gdata_row("record-scene-missing", AR("ok_record_no_scene"), S("scene_00000")),
    gdata_row("val-fraction-above-one", AR(), S("--val-fraction"), "--val-fraction", "1.5"),
    gdata_row("val-fraction-negative", AR(), S("--val-fraction"), "--val-fraction", "-0.1"),
    gdata_row("val-fraction-nan", AR(), S("--val-fraction"), "--val-fraction", "nan"),
    gdata_row("split-path", AR(), S("--split"), "--split", "../x"),
    gdata_row("cut-unknown", AR(), S("--cut"), "--cut", "later", usage=True),
    gdata_row("skip-scenes-negative", AR(), S("--skip-scenes"), "--skip-scenes", "-1"),
    gdata_row("out-under-file", AR(), UNDER_FILE_NAMES, out_arg=under_file, out=under_file),
    gdata_row("out-readonly", AR(), S(readonly_out), out_arg=readonly_out, out=readonly_out, root_skip=True),
    gdata_row("out-proc", AR(), PROC_NAMES, out_arg=PROC_OUT, out=lambda fx, t: Path(PROC_OUT)),
)


# An --out that already exists: nothing may appear in it (not even the lock) ----------------------
EXISTING = {"out_arg": existing_dir, "out": existing_dir}
add(
    R("collect/out-holds-a-dataset", _argv(*COLLECT, "--env", "intersection-v0", "--episodes", "2", "--seed", "11",
                                           "--out", ds("nan_scene")), S(ds("nan_scene")), out=ds("nan_scene")),
    train_row("existing-out/scene-nan", ds("nan_scene"), S("episode_000000.npz"), **EXISTING),
    baseline_row("existing-out/shard-truncated", ds("half_shard"), S("episode_000000.npz"), **EXISTING),
    drive_row("existing-out/ck-guard-kind", ("--checkpoint", ck(GUARD_SRC)), S(ck(GUARD_SRC)), **EXISTING),
    gtrain_row("existing-out/job-truncated", lambda fx, t: fx.guard_data("half_job"), S("train_highway-v0_idm"),
               **EXISTING),
    stress_row("existing-out/config-truncated", "half", S(CFG("half")), **EXISTING),
    traffic_row("existing-out/scene-nan", ds("nan_scene"), S("episode_000000.npz"), **EXISTING),
    selector_row("existing-out/traffic-nan-weights", ck(TRAFFIC_SRC, "nan_weights"), ds(),
                 S(ck(TRAFFIC_SRC, "nan_weights")), **EXISTING),
    attack_row("existing-out/scene-nan", SC("nan_scene"), S("scene_00000.npz"), **EXISTING),
    gdata_row("existing-out/record-truncated", AR("half_record"), S("scene_00000.json"), **EXISTING),
    R("search/existing-out/planner-nosuch", _argv(*SEARCH, "--planner", "nosuch", *S_FAST, "--out", existing_dir),
      S("nosuch"), out=existing_dir),
    R("scenes/existing-out/env-unknown", _argv(*SCENES, "--env", "nope-v0", "--seed", "0", "--count", "1",
                                               "--out", existing_dir), S("nope-v0"), out=existing_dir),
)


# ---------------------------------------------------------------------------------------------
# Checks.


def listing(path: Path | None):
    """None for a path that does not exist; else names, sizes and mtimes of everything in it."""
    if path is None:
        return None
    path = Path(path)
    try:
        st = path.lstat()
    except OSError:
        return None
    if not path.is_dir():
        return {".": (st.st_size, st.st_mtime_ns)}
    entries = {}
    for p in sorted(path.rglob("*")):
        s = p.lstat()
        entries[str(p.relative_to(path))] = (s.st_size if p.is_file() else -1, s.st_mtime_ns)
    return entries


def error_line(prog: str, err: str, usage_ok: bool) -> str:
    lines = [line for line in err.splitlines() if line.strip()]
    assert lines, "nothing on stderr"
    if lines[0].startswith("usage:"):
        assert usage_ok, f"an argparse usage error where a semantic one was expected:\n{err}"
        starts = [i for i, line in enumerate(lines) if line.startswith(prog) and ": error:" in line]
        assert starts, err
        lines = lines[starts[0]:]
    assert len(lines) == 1, f"stderr must be one line, got {len(lines)}:\n{err}"
    return lines[0]


def run_in_process(argv: list[str], capsys) -> tuple[int, str, str]:
    main = riskmap_main if argv[0] == "riskmap" else adversary_main
    try:
        code = main(argv[1:])
    except SystemExit as exit_:
        code = exit_.code
    captured = capsys.readouterr()
    return code, captured.out, captured.err


# Commands with a progress bar (on stderr) run with --quiet, as scripts run them: a bar drawn
# before the error is progress, not an error line.
QUIET = {"collect", "train", "train-baseline", "drive", "check-planner", "evaluate", "guard collect", "guard train",
         "stress-test", "search", "train-traffic", "train-selector", "scenes", "attack", "guard-data", "harden"}


def check_row(row: Row, fx: Fixtures, t: Path, run) -> None:
    argv = row.argv(fx, t)
    if str(PASSWD) in argv and not PASSWD.is_file():
        pytest.skip(f"no {PASSWD} on this system")
    command = " ".join(argv[1:3]) if argv[1] == "guard" else argv[1]
    if command in QUIET and "--quiet" not in argv:
        argv.append("--quiet")
    out = row.out(fx, t) if row.out is not None else None
    watched = [out] + (list(row.watch(fx, t)) if row.watch else [])
    before = [listing(p) for p in watched]
    code, stdout, stderr = run(argv)
    context = f"{' '.join(argv)}\nstdout: {stdout[-2000:]}\nstderr: {stderr[-3000:]}"
    assert "Traceback" not in stderr and "Traceback" not in stdout, context
    assert code == 2, f"exit {code}\n{context}"
    line = error_line(argv[0], stderr, row.usage)
    assert line.startswith(f"{argv[0]} "), context
    assert ": error: " in line, context
    names = row.names(fx, t)
    assert any(name in line for name in names), f"the line names none of {names}\n{context}"
    assert FIX_WORDS.search(line.split(": error: ", 1)[1]), f"the line says nothing to do\n{context}"
    assert "None checkpoint" not in line and "kind=None" not in line, context
    after = [listing(p) for p in watched]
    for path, b, a in zip(watched, before, after):
        assert a == b, f"{path} changed: {b} -> {a}\n{context}"


def _param(row: Row):
    marks = list(row.marks)
    if row.root_skip:
        marks.append(pytest.mark.skipif(IS_ROOT, reason="permissions do not bite for root"))
    return pytest.param(row, id=row.id, marks=marks)


@pytest.mark.parametrize("row", [_param(r) for r in ROWS])
def test_bad_input(row: Row, fx: Fixtures, tmp_path: Path, capsys):
    try:
        check_row(row, fx, tmp_path, lambda argv: run_in_process(argv, capsys))
    finally:
        for path in tmp_path.rglob("*"):           # leave nothing locked for tmp_path's cleanup
            if path.is_dir() and not path.is_symlink():
                path.chmod(0o755)


# A few rows through the installed entry points, to prove the real commands behave the same.
SUBPROCESS_ROWS = ("collect/cr-passwd", "drive/ck-guard-kind", "evaluate/cr-passwd",
                   "stress-test/config-truncated", "train/scene-nan")


@pytest.mark.parametrize("row", [_param(r) for r in ROWS if r.id in SUBPROCESS_ROWS])
def test_bad_input_through_the_entry_point(row: Row, fx: Fixtures, tmp_path: Path):
    bindir = Path(sys.executable).parent

    def run(argv):
        exe = bindir / argv[0]
        command = [str(exe), *argv[1:]] if exe.exists() else [sys.executable, "-m", argv[0], *argv[1:]]
        env = {**os.environ, "OMP_NUM_THREADS": "1"}
        result = subprocess.run(command, capture_output=True, text=True, timeout=120, cwd=REPO, env=env,
                                check=False)
        return result.returncode, result.stdout, result.stderr

    check_row(row, fx, tmp_path, run)


def test_every_command_has_rows():
    commands = {" ".join(row.id.split("/")[:1]) for row in ROWS}
    assert commands >= {
        "collect", "train", "train-baseline", "drive", "check-planner", "evaluate", "tune-goal-variance", "figures-scenes",
        "figures-plans", "guard-collect", "guard-train", "guard-evaluate", "stress-test", "report", "search",
        "search-report", "train-selector", "scenes", "attack", "guard-data", "train-traffic", "harden",
        "export", "adversary-evaluate"}
