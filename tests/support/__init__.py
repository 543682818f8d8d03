"""Code shared by several test modules (imported as tests.support.*; pytest collects nothing here)."""
