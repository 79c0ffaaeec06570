"""The faces of lftransfer: the ``lft`` command (``cli``), the browser page (``viewer``) and the terminal's progress
and tables (``terminal``).

They parse what a user types, call the use cases (:mod:`lftransfer.runs`) and show what those return; they compute
nothing of their own.
"""
