"""Re-process recordings on a Dask cluster: partitions of JSON Lines solved on the workers with
the engine's batch path, written atomically one file per partition, with a manifest that lets an
interrupted campaign resume (``skyfix reprocess``; docs/cluster.md).

Needs the optional extra: ``pip install 'skyfix[cluster]'`` (dask.distributed).
"""

from .partition import Partition, plan_partitions
from .run import ReprocessSummary, reprocess

__all__ = ["Partition", "ReprocessSummary", "plan_partitions", "reprocess"]
