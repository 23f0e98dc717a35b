"""Training runs as jobs: the job (`job`), its state read from its run directory and the local processes that run it
(`runner`), and where jobs run (`executors`: here, or as Ray tasks in `ray_executor`). Used by ``train --seeds`` and
by the experiment grid; it imports nothing of the experiments."""
