"""The `cloth-mg` command line (`main`) and its subcommands' parsers: `batch`, `bag`,
`fidelity` (materials and the textile scenes).
"""
