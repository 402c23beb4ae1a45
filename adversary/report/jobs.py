"""What a report shows of one job: its title and outcome in words, and the pictures of its page
(OUT/jobs/JOB_ID.html): the frame strip, the risk map over time, the attack's own panel and,
for the worst failures, the animation. Pictures go to OUT/jobs/media/, named by job id.
"""

from __future__ import annotations

import zipfile
from pathlib import Path

from adversary.report.frames import (
    animation_frames,
    gif_frame_count,
    load_artifact,
    risk_over_time_image,
    strip_image,
    write_gif,
)
from adversary.report.numbers import planner_name
from rasterize.errors import InputError
from riskmap.infra.atomic import atomic_write

JOBS_DIR = "jobs"          # under the report's directory
MEDIA_DIR = "media"        # under JOBS_DIR


def job_page(job_id: str) -> str:
    """The page of a job, relative to the report's directory."""
    return f"{JOBS_DIR}/{job_id}.html"


def job_title(record: dict) -> str:
    if record.get("recording"):      # a recorded family's scene: its recording and vehicle
        scene = f"{record['env_id']} {Path(record['recording']).stem} vehicle {record['ego_id']}"
    else:
        scene = f"{record['env_id']} seed {record['scene_seed']} episode {record['episode']}"
    return f"{planner_name(record)} | {scene} | {record['attack']}"


def outcome(record: dict) -> str:
    """A finished job's outcome in a few words (a crash attack measures no Safety %, and its
    collisions with other vehicles than the adversary have no type or kinematic value)."""
    if record.get("status", "ok") != "ok":
        return "failed"
    if record["collided"]:
        if record["kinematic_mps"] is None:
            return "collision (not with the adversary)"
        return f"collision ({record['collision_type']}, {record['kinematic_mps']:.1f} m/s)"
    if record["safety_pct"] is None:
        return "no collision"
    return f"no collision, Safety % (danger) {record['safety_pct']:.0f}"


def _save_png(image, path: Path) -> None:
    import io

    buffer = io.BytesIO()
    image.save(buffer, format="PNG", compress_level=1)      # fast; flat colours compress anyway
    atomic_write(path, lambda f: f.write(buffer.getvalue()))


def job_media(artifact: Path, record: dict, out_dir: Path, animate: bool) -> dict:
    """Write one job's pictures into out_dir/jobs/media; returns their paths relative to the
    job's page ({"strip", "risk", "attack_panel", "gif"}, None where there is none), the GIF's
    frame count and notes saying why a picture is missing."""
    media = {"strip": None, "risk": None, "attack_panel": None, "gif": None, "gif_frames": 0, "notes": []}
    if record.get("status") != "ok":
        media["notes"].append("The job failed: it left no scene to draw.")
        return media
    if not artifact.is_file():
        media["notes"].append("No artifact was stored for this job: nothing to draw.")
        return media
    folder = out_dir / JOBS_DIR / MEDIA_DIR
    folder.mkdir(parents=True, exist_ok=True)
    job_id, env_id, title = record["job_id"], record["env_id"], job_title(record)
    try:
        art = load_artifact(artifact)
    except (OSError, ValueError, KeyError, zipfile.BadZipFile, InputError) as error:
        media["notes"].append(f"The job's artifact cannot be read ({type(error).__name__}): nothing to draw.")
        media["unreadable"] = True
        return media
    if art.crash_panel_png is not None:
        (folder / f"{job_id}_attack.png").write_bytes(art.crash_panel_png)
        media["attack_panel"] = f"{MEDIA_DIR}/{job_id}_attack.png"
    if not art.has_frames:
        media["notes"].append("This attack stores no recorded scene (only its own panel), so the "
                              "job has no frames, risk maps or animation.")
        return media
    _save_png(strip_image(art, env_id, f"{title}: the last seconds"), folder / f"{job_id}_strip.png")
    media["strip"] = f"{MEDIA_DIR}/{job_id}_strip.png"
    risk = risk_over_time_image(art, env_id, f"{title}: risk map over time")
    if risk is not None:
        _save_png(risk, folder / f"{job_id}_risk.png")
        media["risk"] = f"{MEDIA_DIR}/{job_id}_risk.png"
    if animate:
        frames, durations = animation_frames(art, env_id, f"{planner_name(record)}, {record['attack']}",
                                             record.get("collision_time_s"))
        if len(frames) >= 2:
            gif = write_gif(frames, durations, folder / f"{job_id}.gif")
            media["gif"] = f"{MEDIA_DIR}/{job_id}.gif"
            media["gif_frames"] = gif_frame_count(gif)
        else:
            media["notes"].append("The episode recorded a single step: nothing to animate.")
    return media
