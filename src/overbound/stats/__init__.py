"""Distribution fits, dependence, extreme values, overbounding."""
