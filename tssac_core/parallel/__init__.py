"""Work spread over Ray: ``ray_cluster`` (where it runs: a Ray started inside the command, or a cluster),
``ray_map`` (a function over items as Ray tasks, in the items' order) and ``mission_shards`` (``evaluate
--workers N``: the batched missions split by index, one task per shard, merged into the serial run's results)."""
