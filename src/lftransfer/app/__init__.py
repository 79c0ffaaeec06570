"""The faces of lftransfer: the ``lft`` command, whole runs on a chosen rig, reports and benchmarks.

This is the only layer that imports both the core and the simulator (``lftransfer.sim``).
"""
