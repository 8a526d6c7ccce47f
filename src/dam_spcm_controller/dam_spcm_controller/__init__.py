"""SPCM controller: compliant-joint impedance, position-joint trajectories and the DAM grasp sequence."""
