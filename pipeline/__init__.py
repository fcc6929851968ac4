"""System-identification pipeline: nominal model -> what the simulation gets wrong -> why -> fix -> gain."""

__version__ = "0.1.0"
