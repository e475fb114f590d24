"""Three simulation tiers over one physical model: full waveform, averaged and steady state."""
