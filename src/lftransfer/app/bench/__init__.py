"""Benchmarks: the peer renderer (Mitsuba's own plugins) that our light field renderer is measured against."""
