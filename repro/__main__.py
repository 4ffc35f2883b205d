"""``python -m repro``: the `repro` command line. This entry shim belongs to the app layer (repro_app)."""

from repro_app.cli import main

main()
