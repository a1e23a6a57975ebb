"""What a run writes: atomic files and volumes (``export``), figures (``plots``), multirun tables (``summary``)."""
