"""Offline evaluation: the paper's metrics (Eq. 14-16), dCAP's trailer-pose metrics, detection,
tracking and latency figures, the report, and parameter sweeps (docs/evaluation.md)."""
