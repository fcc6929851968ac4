"""Tests for pipeline.structures and pipeline.selection (issue 4)."""
