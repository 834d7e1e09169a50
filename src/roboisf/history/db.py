"""The history's database: one SQLite file (default, no server) or a shared PostgreSQL server.

``Database(url)`` with ``url`` a file path (``history.db``), ``sqlite:///path`` or
``postgresql://user:password@host:port/name`` (psycopg 3, ``pip install 'roboisf[history]'``).
Statements are written once with ``?`` placeholders and the portable subset of SQL both speak;
:meth:`Database.transaction` is one transaction: everything in it is written or nothing is (a
process killed halfway leaves the database as it was — SQLite's rollback journal, PostgreSQL's
write-ahead log). A database holding tables of something else is refused, never written into
(``meta.application`` marks a history), and a database error is one line naming the database.

The schema (:data:`SCHEMA_VERSION`, lengths in m, angles in rad, compliances in m/N, times as
ISO 8601 UTC text) is created on first use; ``meta`` holds its version, and a database written by
another version is refused rather than misread.
"""

from __future__ import annotations

import re
import sqlite3
from collections.abc import Iterable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from roboisf.errors import InputError

__all__ = ["APPLICATION", "SCHEMA_VERSION", "Database"]

SCHEMA_VERSION = 1
#: ``meta.application``: what marks a database as a roboisf history
APPLICATION = "roboisf-history"

_PART_COLUMNS = (
    ("fingerprint", "TEXT NOT NULL UNIQUE"),
    ("study", "TEXT NOT NULL"),
    ("source", "TEXT NOT NULL"),
    ("formed_at", "TEXT NOT NULL"),
    ("added_at", "TEXT NOT NULL"),
    ("part_kind", "TEXT NOT NULL"),
    ("part_json", "TEXT NOT NULL"),
    ("robot", "TEXT NOT NULL"),
    ("placement_json", "TEXT NOT NULL"),
    ("tool_json", "TEXT NOT NULL"),
    ("tool_radius", "DOUBLE PRECISION NOT NULL"),
    ("tool_compliance", "DOUBLE PRECISION"),
    ("sheet_thickness", "DOUBLE PRECISION NOT NULL"),
    ("material", "TEXT NOT NULL"),
    ("step_down", "DOUBLE PRECISION NOT NULL"),
    ("rim_band", "DOUBLE PRECISION"),
    ("n_points", "INTEGER NOT NULL"),
    ("n_used", "INTEGER NOT NULL"),
    ("vjm_ratio", "DOUBLE PRECISION"),
    ("vjm_verdict", "TEXT"),
    ("identified_k_json", "TEXT"),
    ("summary_json", "TEXT NOT NULL"),
)
#: per-point columns (m, rad; the terms are normal deviations, m, positive towards the tool side)
POINT_COLUMNS = (
    "idx",
    "lap",
    "depth",
    "wall_angle",
    "x",
    "y",
    "z",
    "nx",
    "ny",
    "nz",
    "used",
    "total_dn",
    "tool_dn",
    "holder_dn",
    "springback_dn",
    "robot_dn",
    "vjm_dn",
)
SHARE_COLUMNS = (
    "book",
    "factor",
    "mean_abs_dx",
    "mean_abs_dy",
    "mean_abs_dz",
    "r_m",
    "share_percent",
)
PART_COLUMNS = tuple(name for name, _ in _PART_COLUMNS)


def _ddl(kind: str) -> list[str]:
    key = (
        "id INTEGER PRIMARY KEY AUTOINCREMENT"
        if kind == "sqlite"
        else "id BIGINT GENERATED ALWAYS AS IDENTITY PRIMARY KEY"
    )
    parts = ", ".join(f"{n} {t}" for n, t in _PART_COLUMNS)
    real = "DOUBLE PRECISION"
    points = ", ".join(
        f"{c} {'INTEGER NOT NULL' if c in ('idx', 'lap', 'used') else real}" for c in POINT_COLUMNS
    )
    shares = ", ".join(
        f"{c} {'TEXT NOT NULL' if c in ('book', 'factor') else real}" for c in SHARE_COLUMNS
    )
    fk = "part_id BIGINT NOT NULL REFERENCES parts(id) ON DELETE CASCADE"
    return [
        "CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL)",
        f"CREATE TABLE IF NOT EXISTS parts ({key}, {parts})",
        f"CREATE TABLE IF NOT EXISTS points ({fk}, {points}, PRIMARY KEY (part_id, idx))",
        f"CREATE TABLE IF NOT EXISTS shares ({fk}, {shares}, PRIMARY KEY (part_id, book, factor))",
        "CREATE INDEX IF NOT EXISTS parts_robot ON parts (robot, formed_at)",
        "CREATE INDEX IF NOT EXISTS parts_kind ON parts (part_kind, formed_at)",
    ]


def _is_postgres(url: str) -> bool:
    return bool(re.match(r"^postgres(ql)?(\+\w+)?://", url))


class Database:
    """A connection to the history (open it with ``with Database(url) as db``).

    Parameters
    ----------
    url : str or Path
        A file path or ``sqlite:///path`` (created if new; its folder must exist), or
        ``postgresql://…`` (the server and database must exist; the tables are created).
    create : bool
        Create the file/tables when missing (``history add``); False refuses a missing file
        (``list``, ``show``, ``trend``, ``predict``: a typo is not an empty history).
    """

    def __init__(self, url: str | Path, *, create: bool = True) -> None:
        text = str(url)
        self.url = text
        self.kind = "postgresql" if _is_postgres(text) else "sqlite"
        self._conn: Any = None
        if self.kind == "postgresql":
            self._conn = self._connect_postgres(text)
        else:
            path = Path(text[len("sqlite:///") :] if text.startswith("sqlite:///") else text)
            if path.is_dir():
                raise InputError("is a folder; expected a history database file", file=path)
            if not path.exists() and not create:
                raise InputError(
                    "no such history database (create it with `roboisf history add`)", file=path
                )
            if not path.parent.is_dir():
                raise InputError("its folder does not exist", file=path)
            if path.exists():
                with path.open("rb") as f:
                    head = f.read(16)
                # an existing file that is not SQLite (or is empty) is a user's, never written
                if head != b"SQLite format 3\x00":
                    raise InputError(
                        "exists and is not a history database (not an SQLite file); "
                        "give another --db",
                        file=path,
                    )
            try:
                # autocommit mode: transactions are explicit (BEGIN IMMEDIATE … COMMIT)
                self._conn = sqlite3.connect(path, isolation_level=None, timeout=30.0)
                self._conn.execute("PRAGMA foreign_keys = ON")
                self._conn.execute("PRAGMA synchronous = FULL")
                self._conn.execute("SELECT count(*) FROM sqlite_master").fetchone()
            except sqlite3.DatabaseError as e:
                raise InputError(f"not a readable SQLite database ({e})", file=path) from None
            self.path = path
        self._prepare()

    @staticmethod
    def _connect_postgres(url: str) -> Any:
        try:
            import psycopg
        except ImportError:
            raise InputError(
                "a PostgreSQL history needs psycopg: pip install 'roboisf[history]'", field="--db"
            ) from None
        try:
            return psycopg.connect(url, autocommit=True, connect_timeout=10)
        except psycopg.Error as e:
            msg = " ".join(str(e).split())
            raise InputError(
                f"cannot connect to the PostgreSQL server: {msg}", field="--db"
            ) from None

    def _tables(self) -> set[str]:
        if self.kind == "sqlite":
            rows = self.query("SELECT name FROM sqlite_master WHERE type = 'table'")
        else:
            rows = self.query(
                "SELECT table_name FROM information_schema.tables "
                "WHERE table_schema = current_schema()"
            )
        return {str(r[0]) for r in rows}

    def _prepare(self) -> None:
        with self.transaction():
            tables = self._tables()
            ours = {"meta", "parts", "points", "shares"}
            mine = ours & tables
            # tables of another application are never written into: an SQLite file with
            # tables but no history, or a server database whose `parts`… are someone else's
            known = "meta" in tables and self.query(
                "SELECT value FROM meta WHERE key = 'application'"
            ) == [(APPLICATION,)]
            if (mine and not known) or (self.kind == "sqlite" and tables and not known):
                raise InputError(
                    "holds tables that are not a roboisf history "
                    f"({', '.join(sorted(tables))}); give another --db",
                    file=self.describe(),
                )
            for stmt in _ddl(self.kind):
                self.execute(stmt)
            row = self.query("SELECT value FROM meta WHERE key = 'schema_version'")
            if not row:
                self.executemany(
                    "INSERT INTO meta (key, value) VALUES (?, ?)",
                    [("schema_version", str(SCHEMA_VERSION)), ("application", APPLICATION)],
                )
            elif row[0][0] != str(SCHEMA_VERSION):
                raise InputError(
                    f"history schema version {row[0][0]}, this roboisf reads {SCHEMA_VERSION}",
                    field="--db",
                )

    # -- statements -------------------------------------------------------------------------
    def _sql(self, sql: str) -> str:
        return sql.replace("?", "%s") if self.kind == "postgresql" else sql

    @contextmanager
    def _errors(self) -> Iterator[None]:
        """A database's own error (locked, disk full, permission, connection lost) as one line
        naming the database; the transaction around it is rolled back."""
        errors: tuple[type[BaseException], ...] = (sqlite3.Error,)
        if self.kind == "postgresql":
            import psycopg

            errors = (psycopg.Error,)
        try:
            yield
        except errors as e:
            msg = " ".join(str(e).split())
            raise InputError(f"database error: {msg}", file=self.describe()) from None

    def execute(self, sql: str, params: Sequence[Any] = ()) -> Any:
        """Run one statement (``?`` placeholders); returns the cursor."""
        with self._errors():
            cur = self._conn.cursor()
            cur.execute(self._sql(sql), tuple(params))
        return cur

    def executemany(self, sql: str, rows: Iterable[Sequence[Any]]) -> None:
        """Run one statement for many parameter rows."""
        with self._errors():
            cur = self._conn.cursor()
            cur.executemany(self._sql(sql), list(rows))

    def query(self, sql: str, params: Sequence[Any] = ()) -> list[tuple[Any, ...]]:
        """Rows of a query (``?`` placeholders)."""
        return list(self.execute(sql, params).fetchall())

    def insert_returning_id(self, sql: str, params: Sequence[Any]) -> int:
        """An INSERT of one row; returns its generated ``id``."""
        if self.kind == "postgresql":
            return int(self.execute(sql + " RETURNING id", params).fetchone()[0])
        return int(self.execute(sql, params).lastrowid)

    @contextmanager
    def transaction(self) -> Iterator[Database]:
        """Everything inside is committed together at the end, or rolled back on an error."""
        if self.kind == "postgresql":
            with self._conn.transaction():
                yield self
            return
        with self._errors():  # "database is locked" after the 30 s timeout
            self._conn.execute("BEGIN IMMEDIATE")
        try:
            yield self
        except BaseException:
            self._conn.execute("ROLLBACK")
            raise
        with self._errors():
            self._conn.execute("COMMIT")

    def close(self) -> None:
        if self._conn is not None:
            self._conn.close()
            self._conn = None

    def __enter__(self) -> Database:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def describe(self) -> str:
        """The database for messages: the file, or the server without its password."""
        if self.kind == "sqlite":
            return str(self.path)
        return re.sub(r"://([^:@/]+):[^@]*@", r"://\1:***@", self.url)
