"""``python -m roboisf``: the ``roboisf`` command (for a venv whose scripts are not on PATH)."""

from roboisf.cli.main import entry

if __name__ == "__main__":
    entry()
