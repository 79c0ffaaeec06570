"""``python -m lftransfer ...`` is the ``lft`` command (for environments without the script on PATH)."""

from lftransfer.app.cli import main

main()
