"""Motion I/O: BVH parsing, human motion, robot reference motions, dataset CSV import."""
