"""Applications: the processes and commands a user starts (``servotau <command>``)."""
