"""Benchmarks by topic (bench/README.md). Run a script from the repository root as
``python -m bench.<topic>.<script>``; scripts import each other as ``bench.<topic>.<script>``."""
