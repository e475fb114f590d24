"""Electronics: the FTR excitation chain (DAC, amplifier, push-pull branches) and the readout front end."""
