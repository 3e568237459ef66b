"""What the API may send to workers and read back: task names and payload schemas.

Only ids, paths and small JSON cross the process boundary; arrays travel as files in the
analysis' own folder. The app imports this module (and nothing else of the worker) to enqueue
work; the worker never imports the app: it learns everything from the payload and reports
through files in the analysis folder and Celery task states.

Analysis folder layout (``work_dir``), written by the worker, read by the app:

    status.json      {"state": queued|running|done|failed|cancelled, "stage": str,
                      "progress": 0..1, "message": str, "error": str|null, "updated": iso time}
                     replaced atomically (temporary name + rename) on every change
    result.json      the DESIGN.md result, present once the analysis is done
    stages/          one output per finished engine stage; a stage whose output exists is skipped
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

#: Celery task names (stable strings: they are the wire contract between api and workers).
ANALYZE_TASK = "coach.analyze"
PREPARE_TASK = "coach.stage.prepare"
CANDIDATES_TASK = "coach.stage.candidates"
SELECT_TASK = "coach.stage.select"

#: The custom Celery state that carries progress meta {"stage", "progress", "message"}.
PROGRESS_STATE = "PROGRESS"

STATES = ("queued", "running", "done", "failed", "cancelled")


@dataclass(frozen=True)
class AnalysisJob:
    """Payload of :data:`ANALYZE_TASK`: everything a worker needs, by path."""

    analysis_id: str
    reference_path: str
    video_path: str
    work_dir: str
    settings: dict = field(default_factory=dict)
    domain_path: str | None = None
    #: How the reference BVH's joints map onto ours (our joint -> BVH joint) and its metres
    #: per file unit, as the club gave them at upload (None: the engine's name tables and
    #: its guess). Carried as data: the engine's domain file does not hold them.
    reference_mapping: dict[str, str] | None = None
    reference_units_to_m: float | None = None

    def to_json(self) -> dict:
        return asdict(self)

    @classmethod
    def from_json(cls, d: dict) -> AnalysisJob:
        return cls(**d)
