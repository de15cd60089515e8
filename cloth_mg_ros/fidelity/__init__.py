"""Physical accuracy: the textile world's standard tests with their exact answers.

`elastica` (the exact heavy elastica of the ASTM D1388 cantilever), `strips` (test specimens
meshed three ways), `settle` (bring a specimen to rest), `cantilever`, `tensile` and `cusick`
(the scenes and what they measure), `swing` (a hanging strip's first mode against the exact
heavy chain, in motion), `incline` (a sheet on a slope against Coulomb's block), `buckle` and
`buckle_exact` (a strip clamped at both ends, pushed together, against the clamped elastica),
`charts` (their pictures). Their command line is `cli.fidelity` (`cloth-mg materials` and the
scenes of `cloth-mg run`), their benchmark `bench.fidelity`. The measured fabrics live in
`physics.fabrics`.
"""
