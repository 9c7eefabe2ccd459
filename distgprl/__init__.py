"""distgprl: reproduction of Dist-GPRL (safety-aware GP skill adaptation with SAC)."""

__version__ = "0.1.0"
