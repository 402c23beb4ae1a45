"""The on-disk result store of a campaign.

    DIR/campaign.json            the resolved config, provenance, and the job list
    DIR/records/<job_id>.json    one record per finished job (written atomically; its presence
                                 is what "finished" means, so a killed campaign loses nothing
                                 finished and resuming never runs a job twice)
    DIR/artifacts/<job_id>.npz   scenes and the last plan, for the report's gallery (written
                                 before the record)
    DIR/index.sqlite             one row per record (key columns + the record's JSON), rebuilt
                                 from records/ on open, for queries and quick listing
"""

from __future__ import annotations

import json
import sqlite3
from pathlib import Path

from riskmap.infra.atomic import atomic_write, write_json

_COLUMNS = ("job_id TEXT PRIMARY KEY, planner TEXT, env_id TEXT, scene_seed INTEGER, "
            "episode INTEGER, attack TEXT, status TEXT, collided INTEGER, record TEXT")


class ResultStore:
    def __init__(self, root: Path):
        self.root = Path(root)
        self.records_dir = self.root / "records"
        self.artifacts_dir = self.root / "artifacts"
        self.records_dir.mkdir(parents=True, exist_ok=True)
        self.artifacts_dir.mkdir(parents=True, exist_ok=True)
        self._db = sqlite3.connect(self.root / "index.sqlite")
        self._db.execute(f"CREATE TABLE IF NOT EXISTS jobs ({_COLUMNS})")
        self._sync_index()

    def _record_path(self, job_id: str) -> Path:
        return self.records_dir / f"{job_id}.json"

    def artifact_path(self, job_id: str) -> Path:
        return self.artifacts_dir / f"{job_id}.npz"

    def _sync_index(self) -> None:
        """Make the index hold exactly the records on disk (a crash may leave it behind)."""
        on_disk = {p.stem for p in self.records_dir.glob("*.json")}
        indexed = {row[0] for row in self._db.execute("SELECT job_id FROM jobs")}
        for job_id in indexed - on_disk:
            self._db.execute("DELETE FROM jobs WHERE job_id = ?", (job_id,))
        for job_id in sorted(on_disk - indexed):
            self._index(json.loads(self._record_path(job_id).read_text()))
        self._db.commit()

    def _index(self, record: dict) -> None:
        self._db.execute(
            "INSERT OR REPLACE INTO jobs VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
            (record["job_id"], record["planner"], record["env_id"], record["scene_seed"],
             record["episode"], record["attack"], record["status"],
             int(bool(record.get("collided"))), json.dumps(record, sort_keys=True)))

    def finished(self) -> set[str]:
        return {p.stem for p in self.records_dir.glob("*.json")}

    def put(self, record: dict, artifact: bytes | None) -> None:
        """Store one finished job: artifact first, then the record that marks it finished."""
        if artifact is not None:
            atomic_write(self.artifact_path(record["job_id"]), lambda f: f.write(artifact))
        write_json(self._record_path(record["job_id"]), record)
        self._index(record)
        self._db.commit()

    def records(self) -> list[dict]:
        """Every finished record, ordered by job id (independent of finishing order)."""
        return [json.loads(row[0]) for row in
                self._db.execute("SELECT record FROM jobs ORDER BY job_id")]

    def close(self) -> None:
        self._db.close()
