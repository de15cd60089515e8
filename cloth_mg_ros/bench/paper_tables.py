"""The paper's solver timings (2008 CPU), shown beside ours by `bench solvers`."""

from __future__ import annotations

# The paper's Table 3 (falling cloth, ms per solve, 2008 CPU) and Table 4 (4491 particles).
PAPER_TABLE3 = {
    "particles": (1189, 2397, 4491, 9919, 19014),
    "pcg": (16.0, 49.2, 130.5, 418.3, 1396.2),
    "mg": (3.3, 9.0, 19.6, 55.5, 147.5),
}
PAPER_TABLE4 = {
    "particles": 4491,
    "pcg": {"silk": 79.0, "wool": 90.9, "cotton": 136.6, "denim": 145.8, "leather": 131.1},
    "mg": {"silk": 17.2, "wool": 17.8, "cotton": 21.9, "denim": 20.9, "leather": 19.6},
}
PAPER_SIZE_MATCH = 0.10  # our particle count within 10% of the paper's counts as "the same"
