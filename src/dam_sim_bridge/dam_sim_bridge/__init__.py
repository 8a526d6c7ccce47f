"""PyBullet stand-in for the three-fingered DAM hand, speaking the device link; simulated
experiments.
"""
