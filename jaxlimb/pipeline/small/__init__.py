"""The few-pixel body strategy: the blurred lit disc fitted as a whole, the centre of brightness as the fallback
(:mod:`jaxlimb.pipeline.small.body`)."""
