"""The one-command demo: broker, master control and two simulated robots completing orders."""
