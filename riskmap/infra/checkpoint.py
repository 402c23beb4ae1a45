"""Checkpoints: safetensors weights plus a JSON sidecar with every config and the metrics; and
the resume state of a training run (`save_state`/`load_state`)."""

from __future__ import annotations

import io
import json
from pathlib import Path

import torch
from safetensors.torch import load_file, save

from rasterize.errors import InputError
from riskmap.infra.atomic import atomic_write, write_json
from riskmap.infra.formats import Format
from riskmap.infra.provenance import provenance

CHECKPOINT_KIND = "riskmap"


def _sidecar_v1(data: dict) -> dict:
    """Sidecars from before versions were kept: a spatial risk-map planner's `sampler` section
    written before `timing`, `keep_gap` and `gap_prediction` existed planned uniform, without gap
    keeping, predicting the others straight."""
    out = dict(data)
    if out.get("kind") == CHECKPOINT_KIND and out.get("planner") != "spacetime" \
            and isinstance(out.get("sampler"), dict):
        out["sampler"] = {"timing": "uniform", "keep_gap": False, "gap_prediction": "straight",
                          **out["sampler"]}
    return out


# Every checkpoint's JSON sidecar, of any kind; `read_sidecar` upgrades older ones.
SIDECAR_FORMAT = Format("checkpoint sidecar", (_sidecar_v1,))

# The folder that holds the `riskmap` package: the repository in a source checkout, where the
# shipped checkpoints/ lie beside it.
TOOLKIT_ROOT = Path(__file__).resolve().parents[2]


def resolve_checkpoint(path: str | Path) -> Path:
    """`path` where it exists as given (a checkpoint's .safetensors or .json, or a folder of
    them); else, for a relative path that the toolkit's own folder holds (a default such as
    `checkpoints/crash_traffic_us101`), that one, so that defaults work from any directory.
    Otherwise `path` unchanged, for the caller's "not found" message."""
    path = Path(path)
    def found(candidate: Path) -> bool:
        return (candidate.is_dir() or candidate.with_suffix(".safetensors").is_file()
                or candidate.with_suffix(".json").is_file())
    if path.is_absolute() or found(path):
        return path
    shipped = TOOLKIT_ROOT / path
    return shipped if found(shipped) else path


def save_checkpoint(path: Path, model: torch.nn.Module, sidecar: dict,
                    kind: str = CHECKPOINT_KIND) -> Path:
    """Write `path` (.safetensors) and `path.with_suffix('.json')`, each atomically.

    `kind` tags the sidecar so that a loader refuses weights of another model family.
    """
    path = Path(path).with_suffix(".safetensors")
    state = {k: v.detach().cpu().contiguous() for k, v in model.state_dict().items()}
    atomic_write(path, lambda f: f.write(save(state)))
    write_json(path.with_suffix(".json"), SIDECAR_FORMAT.stamp({"kind": kind, **provenance(), **sidecar}))
    return path


def save_state(path: Path, state: dict) -> None:
    """Write a training run's resume state (tensors and plain values: weights, optimizer, epoch,
    log) in one atomic write, so that it is the run's one commit point per epoch: a run killed
    anywhere resumes from the last state written whole, and the files derived from it (log,
    checkpoints) are written again from it."""
    buffer = io.BytesIO()
    torch.save(state, buffer)
    atomic_write(path, lambda f: f.write(buffer.getvalue()))


def load_state(path: Path) -> dict:
    """A resume state written by `save_state`; an unreadable one is an InputError."""
    import pickle

    try:
        return torch.load(path, weights_only=True)
    except (OSError, RuntimeError, EOFError, ValueError, pickle.UnpicklingError) as err:
        raise InputError(f"{path} is unreadable ({type(err).__name__}); delete {Path(path).parent} "
                         "and start again") from None


# What a checkpoint of each kind holds and the command that makes one (for messages).
KINDS = {
    "riskmap": ("risk-map planner", "`riskmap train`"),
    "bc": ("behaviour-cloning baseline", "`riskmap train-baseline`"),
    "guard_tgat": ("guard (TGAT)", "`riskmap guard train`"),
    "traffic_cvae": ("CRASH traffic model", "`adversary train-traffic`"),
    "crash_selector": ("CRASH selector", "`adversary train-selector`"),
}


def kind_words(kind) -> tuple[str, str]:
    """(what a `kind` checkpoint is, the command that trains one), for messages."""
    return KINDS.get(kind, (f"{kind!r}", "the command that trains it"))


def read_sidecar(path: Path, kind: str = CHECKPOINT_KIND) -> dict:
    """The JSON sidecar of checkpoint `path` (without suffix), which must be of `kind`, in today's
    layout (`SIDECAR_FORMAT` upgrades older ones); anything else (missing, unreadable, of no or
    another kind, of a newer format) is an InputError naming the path. A relative path not found
    here is looked for in the toolkit's own folder (`resolve_checkpoint`)."""
    path = resolve_checkpoint(path)
    weights = path.with_suffix(".safetensors")
    sidecar = path.with_suffix(".json")
    what, made_by = kind_words(kind)
    fix = f"pass a {what} checkpoint from {made_by}"
    if not weights.is_file() or not sidecar.is_file():
        raise InputError(f"checkpoint {path} not found (need {weights.name} and {sidecar.name}); "
                         f"train one with {made_by} or pass a path under checkpoints/")
    try:
        data = json.loads(sidecar.read_text())
    except (OSError, ValueError):
        raise InputError(f"{sidecar} is not valid JSON (damaged, or not a checkpoint sidecar); "
                         f"{fix}") from None
    if not isinstance(data, dict) or data.get("kind") is None:
        raise InputError(f"{sidecar} is not a checkpoint sidecar (it names no kind); {fix} (the "
                         ".json that training wrote beside the .safetensors)")
    if data["kind"] != kind:
        theirs = kind_words(data["kind"])[0]
        raise InputError(f"checkpoint {path} is a {theirs} checkpoint (kind {data['kind']!r}), not "
                         f"a {what} one; {fix}")
    return SIDECAR_FORMAT.read(data, where=sidecar)


def load_tensors(path: Path) -> dict[str, torch.Tensor]:
    """The tensors of checkpoint `path` (.safetensors); unreadable weights, or weights with NaN or
    inf in them, are an InputError naming the file."""
    from safetensors import SafetensorError

    weights = resolve_checkpoint(path).with_suffix(".safetensors")
    try:
        state = load_file(str(weights))
    except (SafetensorError, OSError, ValueError, RuntimeError) as err:
        reason = (str(err).splitlines() or [type(err).__name__])[0][:200]
        raise InputError(f"checkpoint weights {weights} are unreadable ({reason}); the file is "
                         "truncated or not a .safetensors checkpoint: pass another checkpoint or "
                         "train it again") from None
    bad = [name for name, tensor in state.items()
           if tensor.is_floating_point() and not bool(torch.isfinite(tensor).all())]
    if bad:
        more = f" and {len(bad) - 1} more" if len(bad) > 1 else ""
        raise InputError(f"checkpoint weights {weights} hold NaN or inf (in {bad[0]}{more}); the "
                         "run that wrote them diverged or the file is damaged: pass another "
                         "checkpoint or train it again") from None
    return state


def load_weights(model: torch.nn.Module, path: Path, fix: str) -> torch.nn.Module:
    """Load `path`.safetensors into `model` (eval mode); unreadable or non-finite weights are an
    InputError (`load_tensors`), a mismatch one ending in `fix`."""
    state = load_tensors(path)
    try:
        model.load_state_dict(state)
    except (RuntimeError, OSError) as err:
        reason = " ".join(str(err).split())[:300]          # one line, however long the list
        raise InputError(f"checkpoint {path} does not match its config ({reason}); {fix}") from None
    return model.eval()


def route_settings_of(sidecar: dict) -> dict | None:
    """The route rule a planner was trained with when its data was recorded traffic
    (`speed_limit_mps`, `route_accel_mps2`, derived at collection), or None (simulated data: the
    simulator's lanes carry their own limits)."""
    derived = sidecar.get("dataset", {}).get("derived") or {}
    if "speed_limit_mps" not in derived:
        return None
    return {"speed_limit_mps": float(derived["speed_limit_mps"]),
            "route_accel_mps2": float(derived["route_accel_mps2"])}


def sidecar_section(data: dict, name: str, path: Path, build=dict):
    """`build(**data[name])`: one section of checkpoint `path`'s sidecar, made into its config
    (`build`, e.g. a frozen config dataclass); a missing or malformed section (an edited or
    truncated sidecar) is an InputError naming the sidecar and the section."""
    require_sections(data, path, {name: ()})
    try:
        return build(**data[name])
    except (TypeError, ValueError) as error:
        raise InputError(f"checkpoint {path}: the {name!r} section of its sidecar does not fit "
                         f"this version ({error}); {_sidecar_fix(path)}") from None


def require_sections(data: dict, path: Path, sections: dict[str, tuple[str, ...]]) -> None:
    """Check that checkpoint `path`'s sidecar holds each of `sections` as a mapping with at least
    the keys listed for it, so that a loader reading them fails in one line naming the sidecar
    (an edited or truncated one) instead of with a KeyError halfway through."""
    for name, keys in sections.items():
        section = data.get(name)
        if not isinstance(section, dict):
            raise InputError(f"checkpoint {path}: its sidecar has no {name!r} section (edited or "
                             f"truncated); {_sidecar_fix(path)}")
        missing = [key for key in keys if key not in section]
        if missing:
            raise InputError(f"checkpoint {path}: the {name!r} section of its sidecar has no "
                             f"{', '.join(map(repr, missing))} (edited or truncated); "
                             f"{_sidecar_fix(path)}")


def _sidecar_fix(path: Path) -> str:
    """What to do about a sidecar that lacks what its loader needs: only training writes a whole
    one. Names the file as `read_sidecar` found it."""
    sidecar = resolve_checkpoint(path).with_suffix(".json")
    return f"use the {sidecar} that training wrote, or train the checkpoint again"
