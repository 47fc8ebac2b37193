"""The report: paper figures, the report page and its key metrics."""
