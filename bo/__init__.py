"""bo package."""
