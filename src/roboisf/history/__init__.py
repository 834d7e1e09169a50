"""The cell's history: analysed parts in a database (SQLite file or PostgreSQL server).

- :mod:`roboisf.history.db` — the connection and schema (one transaction per part);
- :mod:`roboisf.history.store` — ``analyze`` results folders in (``add``) and out (``list``,
  ``show``, per-point tables for :mod:`roboisf.learn`);
- :mod:`roboisf.history.trend` — per robot, part kind or tool over time.

Optional: PostgreSQL needs ``pip install 'roboisf[history]'`` (psycopg); the SQLite file needs
nothing beyond Python. docs/history.md.
"""
