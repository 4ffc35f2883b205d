"""``python -m repro_app``: the same as ``repro``."""

from repro_app.cli import main

main()
