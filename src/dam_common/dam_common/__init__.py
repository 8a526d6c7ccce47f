"""Plumbing shared by every DAM node package.

- :mod:`dam_common.config`: the validated configuration (``config/dam.yaml``), pure Python.
- :mod:`dam_common.realtime`: real-time scheduling and process helpers, pure Python.
- :mod:`dam_common.node`: ``run_node`` (start-up errors, signals, clean shutdown) and the
  parameters every node declares (rclpy).
"""
