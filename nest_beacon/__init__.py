"""The nest beacon: a radio transmitter at the nest."""
