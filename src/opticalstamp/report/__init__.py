"""The main job's output: figures (matplotlib) and the HTML page of ``opticalstamp report``."""
