"""Benchmarks (``make bench``): each module exposes ``run(quick: bool) -> str`` returning a Markdown
section; ``python -m pipeline.bench`` runs them all and writes BENCHMARKS.md. Speed is measured here,
never asserted in timed tests."""
