"""``vda-fleetsim``: a fleet under master control, simulated faster than real time on one fake
clock, to size a fleet for a floor and to judge a change of layout or of traffic control
(docs/fleetsim.md). The engine (:mod:`vda_fleetsim.simulation`) runs the real master service
and the real simulated vehicles; only MQTT and time are replaced."""
