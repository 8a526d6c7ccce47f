"""SPCM controller: compliant-joint impedance, position-joint trajectories, DAM sequence."""
