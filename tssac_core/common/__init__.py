"""What every room shares, importing nothing from the project: ``files`` (writes that a crash never tears),
``errors`` (the checkpoint error the torch-free and the torch parts raise alike) and ``stats`` (evaluation
statistics: Wilson and bootstrap intervals, the tail)."""
