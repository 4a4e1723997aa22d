//! Noise twin: turns a noise-free simulated waveform into a GEDI-like one.
