"""The applications: the demo (main job), the paper's cases and the plots."""
