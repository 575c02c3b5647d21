"""``vda-inspect``: a passive check of the VDA 5050 traffic on a broker (docs/inspect.md). A tool
on top of the protocol core (:mod:`vda5050`), using master control's factsheet checks
(:mod:`vda_master.capabilities`) and the vehicle's optional-field walk to judge a master
control of any maker against the factsheets its vehicles publish."""
