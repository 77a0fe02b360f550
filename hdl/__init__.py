"""rosgate hardware components (Amaranth).

One package per concern. Nothing in here imports a simulator.
"""
