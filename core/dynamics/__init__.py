"""On-machine time series: checks, identification of the measuring loop, correction, vibrations."""
