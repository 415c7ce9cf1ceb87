"""Benchmarks: ``make bench`` runs every ``bench_*.py`` module here in turn.

Each module defines ``main() -> None`` that prints its own table. Set
``BENCH_ONLY=name1,name2`` to run a subset (names without the ``bench_`` prefix), and
``BENCH_QUICK=1`` for a fast smoke run with fewer repetitions.
"""
