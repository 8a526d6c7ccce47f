"""Driver node for the DAM hand: device link, /joint_states, joint commands, diagnostics,
recording.
"""
