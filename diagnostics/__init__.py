"""Diagnostic studies of trained models and rollouts, each run as `python -m diagnostics.<name>`.

Outside the pimann package, so that no pipeline stage imports them and their edits rerun
nothing (tests/test_import_order.py).
"""
