"""The `treegen` commands, one thin click module each: parse flags, call the API, print.

    make.py     treegen make     → api.plan_make / api.run_make
    info.py     treegen info     → api.info
    forest.py   treegen forest   → api.run_forest (forest/)
    batch.py    treegen batch    → batch.py (catalogues on Dask)
    preview.py  treegen preview  → preview.py
    species.py  treegen species  → species_list.py
    flags.py    the make options as click options, each defined once (types and defaults from
                options.DEFAULTS)
    usage.py    click's own parse errors worded as one line (the entry point prints them)

The root group and the entry point are in ../cli.py. Commands import the API, not the stages
(tests/test_architecture.py checks).
"""
