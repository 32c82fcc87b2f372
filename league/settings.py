"""League server settings: pydantic-settings read from ``SLIPSTREAM_*`` environment variables."""

from __future__ import annotations

from pathlib import Path

from pydantic import Field
from pydantic_settings import BaseSettings, SettingsConfigDict

MiB = 1024 * 1024


class Settings(BaseSettings):
    """Everything the league server can be configured with; no hidden globals."""

    model_config = SettingsConfigDict(env_prefix="SLIPSTREAM_", extra="ignore")

    data_dir: Path = Field(default=Path("slipstream-data"), description="Database and files.")
    database_url: str | None = Field(
        default=None, description="SQLAlchemy URL; default: SQLite in the data directory."
    )
    storage_url: str | None = Field(
        default=None,
        pattern=r"^$|^s3://[a-z0-9][a-z0-9.-]{1,61}[a-z0-9](/.*)?$",
        description="Model files and traces in object storage (s3://bucket/prefix); "
        "default: the data directory's files folder.",
    )
    s3_endpoint_url: str | None = Field(
        default=None, description="S3 API endpoint (MinIO, Ceph...); default: AWS S3."
    )
    max_upload_bytes: int = Field(default=50 * MiB, gt=0, description="Model upload cap.")
    upload_timeout_seconds: float = Field(
        default=300.0, gt=0.0, description="Time a model upload's body may take to arrive."
    )
    max_body_bytes: int = Field(
        default=16 * 1024, gt=0, description="Body cap of every route but the model upload."
    )
    body_timeout_seconds: float = Field(
        default=10.0, gt=0.0, description="Time any other request body may take to arrive."
    )
    rate_limit_per_second: float = Field(
        default=50.0, ge=0.0, description="Sustained requests per client; 0 turns limiting off."
    )
    rate_limit_burst: int = Field(default=200, gt=0, description="Requests a client may burst.")
    sqlite_busy_timeout_ms: int = Field(default=5000, ge=0)
    lease_seconds: float = Field(default=30.0, gt=0.0, description="Job lease length.")
    poll_seconds: float = Field(
        default=1.0, gt=0.0, description="Idle wait of workers and the scheduler."
    )
    race_memory_mb: int = Field(default=1024, gt=0, description="Race child address space.")
    race_cpu_seconds: int = Field(default=600, gt=0, description="Race child CPU time.")
    race_wall_seconds: float = Field(default=900.0, gt=0.0, description="Race wall time.")
    validation_concurrency: int = Field(
        default=2, gt=0, description="Uploads validated at once, each in its own child process."
    )
    validation_queue: int = Field(
        default=8, ge=0, description="Uploads that may wait for a validation slot; more get 503."
    )
    validation_wait_seconds: float = Field(
        default=30.0, gt=0.0, description="Longest wait for a validation slot before 503."
    )
    validation_cpu_seconds: int = Field(
        default=10, gt=0, description="CPU time of one upload's validation child."
    )
    validation_wall_seconds: float = Field(
        default=20.0, gt=0.0, description="Wall time of one upload's validation child."
    )
    round_races_per_model: int = Field(
        default=2, ge=1, description="Head-to-model races per model per round (k)."
    )
    round_max_cars: int = Field(default=4, ge=2, le=6, description="Cars per head-to-model race.")
    orphan_grace_seconds: float = Field(
        default=600.0,
        ge=0.0,
        description="Temp and unreferenced files younger than this survive the start-up sweep.",
    )
    # How races judge models, and each racer's share of the queue: see docs/league-api.md.
    race_step_budget_ms: float | None = Field(
        default=None,
        gt=0.0,
        description="CPU time a model's step may take in a race; default: the validator's "
        "per-step cap. A model whose fastest of race_step_window steps is over it is out "
        "of the race.",
    )
    race_step_window: int = Field(
        default=10, ge=1, description="Steps the race step budget is judged over."
    )
    fault_dnf_limit: int = Field(
        default=3,
        ge=1,
        description="DNFs for model faults (NaN/inf, too slow) in one event that suspend an "
        "entry from it.",
    )
    max_entries_per_racer: int = Field(
        default=5, ge=1, description="Entries one racer may have in one event."
    )
    max_queued_jobs_per_racer: int = Field(
        default=100,
        ge=1,
        description="Evaluation jobs one racer may have queued or running; an entry that "
        "would pass it is refused (429).",
    )
    validation_per_racer: int = Field(
        default=2,
        ge=1,
        description="Uploads of one racer being validated or waiting for a slot; more get 429.",
    )
    # What one connection may cost: see docs/deploy.md ("Connections").
    max_header_bytes: int = Field(
        default=32 * 1024,
        ge=1024,
        description="Request line and header fields of one request; more get 431 and the "
        "connection is closed.",
    )
    max_header_count: int = Field(
        default=100, ge=8, description="Header fields of one request; more get 431."
    )
    header_timeout_seconds: float = Field(
        default=10.0,
        gt=0.0,
        description="Time a request's line and headers may take to arrive, counted from the "
        "connection's start or the head's first byte; then 408 (or, idle, just closed).",
    )
    keep_alive_seconds: float = Field(
        default=5.0, gt=0.0, description="Idle time of a connection between two requests."
    )
    max_connections: int = Field(
        default=1000,
        ge=1,
        description="Open connections (and requests in progress) of one server process; a "
        "request beyond it gets 503. Keep the open-files limit (LimitNOFILE) well above it.",
    )

    # Training jobs (league.training): quotas and the sandbox, see docs/deploy.md ("Training").
    training_jobs_total: int = Field(
        default=1, ge=1, description="Training jobs running at once on the league; more wait."
    )
    training_jobs_per_racer: int = Field(
        default=1, ge=1, description="Training jobs of one racer running at once; more wait."
    )
    training_queued_per_racer: int = Field(
        default=3,
        ge=1,
        description="Training jobs one racer may have queued or running; more are refused (429).",
    )
    training_max_minutes: float = Field(
        default=60.0, gt=0.0, description="Longest budget one training job may ask for."
    )
    training_minutes_per_month: float = Field(
        default=600.0,
        ge=0.0,
        description="Training minutes one racer may use per calendar month (UTC); a job "
        "whose budget would pass what is left is refused (429) until the month resets.",
    )
    training_workers: int | None = Field(
        default=None,
        ge=0,
        description="Env worker processes of one training job; default: the host's cores "
        "shared among training_jobs_total jobs.",
    )
    training_nice: int = Field(
        default=10,
        ge=0,
        le=19,
        description="Niceness of trainers and their jobs: on a shared host the API and "
        "races get the CPU first.",
    )
    training_memory_mb: int = Field(
        default=4096, gt=0, description="Address space of each process of a training job."
    )
    training_processes: int = Field(
        default=512, gt=0, description="Processes and threads a training job may run at once."
    )
    training_file_mb: int = Field(
        default=1024, gt=0, description="Largest file a training job may write."
    )
    training_disk_mb: int = Field(
        default=4096,
        gt=0,
        description="Disk a training job's folder may take; past it the job is stopped.",
    )
    training_unconfined: bool = Field(
        default=False,
        description="Run training jobs without the bubblewrap sandbox on a host that cannot "
        "provide it. Racers' reward functions then run with the trainer's rights: only for "
        "a league whose racers are all trusted (docs/deploy.md).",
    )

    @property
    def db_url(self) -> str:
        """The database URL in use (the embedded SQLite file unless one was given)."""
        if self.database_url:
            return self.database_url
        return f"sqlite:///{(self.data_dir / 'league.db').resolve()}"

    @property
    def storage_dir(self) -> Path:
        """Where content-addressed files (models, race traces) live."""
        return self.data_dir / "files"
