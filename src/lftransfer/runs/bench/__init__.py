"""Benchmarks: the live step timed as users run it (``step``), its ray-casting floor (``floor``), the fast path's
accuracy (``accuracy``), Mitsuba's own path tracer on the light field job (``peer``) and calibration accuracy over
hidden truths (``calibration``)."""
