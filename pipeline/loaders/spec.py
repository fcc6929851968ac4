"""What a loader needs to know about one file: format, text options and size bounds."""

from __future__ import annotations

from dataclasses import dataclass

DEFAULT_MAX_BYTES = 2 << 30          # 2 GiB: file size, and decoded size of .mat/Parquet columns
DEFAULT_MAX_SAMPLES = 1_000_000      # rows (samples) per file: the diagnosis needs about 2.5 kB and 0.2 ms a
                                     # sample (2 000 000 rows: 4.9 GB peak, 7.5 min); 50 000 000 let it run out of memory

SUFFIXES = {".csv": "csv", ".txt": "csv", ".parquet": "parquet", ".pq": "parquet", ".mat": "mat",
            ".dat": "table"}


@dataclass(frozen=True)
class ReadSpec:
    """Resolved read options of one file (``data`` merged with an experiment's own keys).

    ``delimiter`` None means "," for csv and any run of whitespace for table; ``comment`` None means
    no comment character (the config's default "#" for table is resolved by the caller)."""

    format: str | None = None                  # csv | table | parquet | mat; None: from the suffix
    columns: tuple[str, ...] | None = None     # table: every column's name, in file order
    delimiter: str | None = None
    decimal: str = "."
    comment: str | None = None
    skip_rows: int = 0
    max_bytes: int = DEFAULT_MAX_BYTES
    max_samples: int = DEFAULT_MAX_SAMPLES
