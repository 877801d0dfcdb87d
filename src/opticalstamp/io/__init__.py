"""The only place results meet the disk: JSON with provenance, atomic files, sets of files
and folders, images and datasets."""
