"""Physical effects that can be added to a device, each nested at zero."""
