"""The `cloth-mg` command line (`main`) and its subcommands' parsers: `batch`, `bag`, `run`
with its scenes `fidelity` (and `cloth-mg materials`: the textile tests of the package
`fidelity`) and `dressing_run`.
"""
