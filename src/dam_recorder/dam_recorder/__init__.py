"""Recorder of the DAM hand's topics into rosbag2 bags (MCAP or sqlite3), written with the
``rosbags`` library.

The pure core (no rclpy) is :mod:`~dam_recorder.type_description` (message definitions and
hashes), :mod:`~dam_recorder.cdr_end` (where a CDR message ends), :mod:`~dam_recorder.qos`,
:mod:`~dam_recorder.selection`, :mod:`~dam_recorder.metadata`, :mod:`~dam_recorder.bag_writer`,
:mod:`~dam_recorder.writing` (the recorder's writing pipeline),
:mod:`~dam_recorder.episode_events` and :mod:`~dam_recorder.recovery`;
:mod:`~dam_recorder.recorder_node` is the thin ROS layer.
"""
