"""Many designs: cheap evaluation, the journalled runner (process pool or Dask), the
design search and the assembly tolerancing."""
