"""Demonstration datasets in the LeRobot v3.0 layout: collection, writing, reading, checking.

See docs/reference/dataset_format.md for every file and field.
"""

from rmbench.data.collect import CollectConfig, CollectSummary, collect
from rmbench.data.writer import DatasetError

__all__ = ["CollectConfig", "CollectSummary", "DatasetError", "collect"]
