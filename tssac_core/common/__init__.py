"""What every room shares, importing nothing from the project: ``files`` (writes that a crash never tears),
``errors`` (bad input a user can fix, and the checkpoint error the torch-free and the torch parts raise alike),
``cli`` (what every command line shares: one clear line and exit code 2 on bad input) and ``stats`` (evaluation
statistics: Wilson and bootstrap intervals, the tail)."""
