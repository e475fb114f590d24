"""Physics of the resonator, its electrodes and its thermal state."""
