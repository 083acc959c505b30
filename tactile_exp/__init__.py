"""tactile_exp: reproduce and extend Gao et al. (ICRA 2016) haptic-adjective classification."""

__version__ = "0.1.0"
