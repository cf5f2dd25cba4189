"""Tests of experiment scripts."""
