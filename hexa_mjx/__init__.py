"""hexa_mjx: a JAX-native, massively parallel hexapod trainer on MuJoCo MJX."""
