"""Child processes of ``fly``: starting, watching and stopping them (:mod:`~mavlink_bridge.processes.children`), and
the fork server that starts a crew's processes from one interpreter that did their imports
(:mod:`~mavlink_bridge.processes.fork_server`). Standard library only; imports nothing else of ``mavlink_bridge``.
"""
