"""The report: paper figures, the report page and its key metrics.

A package's summary only (hence so short): its modules hold the code."""
