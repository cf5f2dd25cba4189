"""physsim tests."""
