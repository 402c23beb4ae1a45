"""The fine-tuning data of a hardening round: attack windows mixed with natural windows.

A round's dataset is a `riskmap collect` dataset directory (`riskmap.data.dataset.DemoDataset`
reads it as any other) whose manifest is the natural dataset's and whose index lists

    every attack shard made so far (ROUND/windows/<scene>.npz of this round and the earlier
        ones; group "adversarial"): attacks on earlier planners stay valid demonstrations;
    natural training shards of the natural dataset (by absolute path; group: the shard's
        recorded group, else "natural-<episode>"), drawn in a seeded order until natural windows
        make `natural_share` of the training windows;
    every natural shard the original checkpoint validated on (its held-out groups, else the last
        episodes as `riskmap train` split them), so a round validates on exactly the original's
        validation windows.

`validation_groups` names the last, for `riskmap train --val-groups`.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from rasterize.errors import InputError
from rasterize.scene_io import pack_scenes
from riskmap.data.collect import INDEX, MANIFEST
from riskmap.data.dataset import DemoDataset, load_manifest
from riskmap.infra.atomic import write_json, write_npz

ADVERSARIAL_GROUP = "adversarial"


def write_attack_shard(path: Path, scenes: tuple, info: dict) -> None:
    """One attack's windows as a shard (atomic), its info beside it (`.json`) as the commit point."""
    path = Path(path)
    if scenes:
        arrays = pack_scenes(list(scenes))
        arrays["episode_info"] = np.frombuffer(json.dumps(info, sort_keys=True).encode(), np.uint8)
        write_npz(path.with_suffix(".npz"), arrays)
    write_json(path.with_suffix(".json"), info)


def _natural_group(entry: dict) -> str:
    return entry.get("group") or f"natural-{entry['episode']}"


def natural_split(natural: Path, sidecar: dict) -> tuple[list[dict], list[dict]]:
    """(training, validation) index entries of the natural dataset as the original checkpoint's
    training split them: its recorded `val_groups`, else its last `val_fraction` of episodes."""
    try:
        entries = [e for e in json.loads((Path(natural) / INDEX).read_text())["shards"] if e["windows"] > 0]
    except (OSError, ValueError, KeyError, TypeError):
        raise InputError(f"--natural {natural}: {INDEX} is missing or unreadable; pass a dataset from "
                         "`riskmap collect`") from None
    held = set(sidecar.get("dataset", {}).get("val_groups") or ())
    if held:
        val = [e for e in entries if e.get("group") in held]
    else:
        n_val = max(1, math.ceil(sidecar["train"]["val_fraction"] * len(entries)))
        val = entries[-n_val:]
    train = [e for e in entries if e not in val]
    if not val or not train:
        raise InputError(f"--natural {natural}: cannot rebuild the checkpoint's split (validation groups "
                         f"{sorted(held) or 'by episode'}); pass the dataset the checkpoint was trained on")
    return train, val


SEARCH_SHARD_PREFIX = "search_"     # window shards made from search failures (loop.round_search_windows)


def _shard_windows(shard: Path) -> int:
    return int(json.loads(Path(shard).with_suffix(".json").read_text()).get("windows", 0))


def cap_search_shards(shards: list[Path], search_share: float, seed: int) -> tuple[list[Path], dict]:
    """Keep the search shards (named search_*) in a seeded random order while their windows stay
    within `search_share` of all attack windows, i.e. at most search_share / (1 - search_share)
    times the CRASH shards' windows; the CRASH shards are all kept. Returns the shards kept and
    a summary of what was dropped."""
    crash = [s for s in shards if not Path(s).name.startswith(SEARCH_SHARD_PREFIX)]
    found = [s for s in shards if Path(s).name.startswith(SEARCH_SHARD_PREFIX)]
    crash_windows = sum(_shard_windows(s) for s in crash)
    allowed = math.floor(crash_windows * search_share / (1.0 - search_share) + 1e-9)
    kept, kept_windows = [], 0
    for i in np.random.default_rng(seed).permutation(len(found)):
        windows = _shard_windows(found[int(i)])
        if kept_windows + windows <= allowed:
            kept.append(found[int(i)])
            kept_windows += windows
    kept_set = set(map(str, kept))
    summary = {"search_share": search_share, "crash_windows": crash_windows,
               "search_windows_found": sum(_shard_windows(s) for s in found), "search_windows_kept": kept_windows,
               "search_shards_found": len(found), "search_shards_kept": len(kept)}
    return crash + [s for s in found if str(s) in kept_set], summary


def write_round_dataset(out: Path, natural: Path, sidecar: dict, attack_shards: list[Path],
                        natural_share: float, seed: int) -> dict:
    """Write the round's dataset under `out` (module docstring); returns its summary."""
    out, natural = Path(out), Path(natural).resolve()
    manifest = load_manifest(natural)
    train, val = natural_split(natural, sidecar)
    adversarial = []
    for path in attack_shards:
        info = json.loads(Path(path).with_suffix(".json").read_text())
        if info.get("windows"):
            adversarial.append({"file": str(Path(path).with_suffix(".npz").resolve()), "episode": len(adversarial),
                                "windows": info["windows"], "group": ADVERSARIAL_GROUP})
    attack_windows = sum(e["windows"] for e in adversarial)
    if not attack_windows:
        raise InputError("no attack gave training windows this round; attack more scenes (--count) or "
                         "check the attacks under ROUND/attack")
    wanted = round(attack_windows * natural_share / (1.0 - natural_share)) if natural_share < 1 else math.inf
    order = np.random.default_rng(seed).permutation(len(train))
    chosen, natural_windows = [], 0
    for i in order:
        if natural_windows >= wanted:
            break
        chosen.append(train[int(i)])
        natural_windows += train[int(i)]["windows"]
    base = len(adversarial)
    shards = adversarial + [{"file": str(natural / e["file"]), "episode": base + k, "windows": e["windows"],
                             "group": _natural_group(e)} for k, e in enumerate(chosen + val)]
    summary = {"attack_windows": attack_windows, "attack_shards": len(adversarial),
               "natural_windows": natural_windows, "natural_shards": len(chosen),
               "validation_windows": sum(e["windows"] for e in val),
               "validation_groups": sorted({_natural_group(e) for e in val}),
               "natural_share": natural_share, "natural": str(natural)}
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / MANIFEST, {**manifest, "hardening": summary})
    write_json(out / INDEX, {"shards": shards})
    DemoDataset(out)          # readable as a dataset, or an error naming what is wrong, now
    return summary
