"""The use cases: a whole run on a chosen rig (``pipeline``, ``rigs``), a live sequence (``sequence``), a study
over a setting (``study``), an effect measured against its ground truth (``effects``), the ground truth's pool
(``reference_pool``, ``cluster``), the run folder (``run_folder``), the checks made before any work (``paths``,
``memory``) and the benchmarks (``bench``).

They print nothing: progress goes to a callback and results come back as typed objects or report.json, written
through :mod:`lftransfer.reports`. With the faces (:mod:`lftransfer.app`), this is the only layer that imports both
the core and the simulator (``lftransfer.sim``), and it reads the hidden truth only through the oracle.
"""
