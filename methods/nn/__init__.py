"""Building blocks shared by the learned methods (pure torch, no I/O)."""
