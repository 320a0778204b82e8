"""Many sessions at once on Dask: ``pipeline fleet`` (issue 17)."""
