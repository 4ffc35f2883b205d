"""Layer 4: everything that steps an environment with a learner: building and running one run (``api``), the
online and offline loops and their shared parts, and generating offline datasets from recorded policies."""
