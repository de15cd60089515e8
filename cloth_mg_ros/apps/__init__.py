"""Whole jobs built on the simulation: the headless runner (`runner`), batches of runs
(`batch`) on a cluster (`cluster`), the install-time warm-up (`warmup`) and the process's
memory setting (`memory`).
"""
