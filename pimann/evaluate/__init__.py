"""Evaluation (paper Sec. IV): the metrics, the claims, command following, the data report and
its reference, and the results reader the report's figures use."""
