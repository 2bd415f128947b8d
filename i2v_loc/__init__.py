"""i2v-loc: infrastructure-based LiDAR localization of articulated vehicles."""

__version__ = "0.1.0"
