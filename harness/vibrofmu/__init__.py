"""vibrofmu harness: build the FMUs, run them under FMPy, check them against references."""
