"""What a run leaves for people to read: report.json and the run's pictures (``report``, ``figures``), the HTML
reports (``calibration_report``, ``study_report``, through ``templating``) and docs/results.md's generator
(``results`` and its sections ``results_*``).

Reports format what the use cases (:mod:`lftransfer.runs`) measured; they never run anything themselves.
"""
