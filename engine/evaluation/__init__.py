"""Developer code, not in the extension: how good a reconstruction or a camera estimate is,
measured against a ground truth, in units of the true cable radius; and the outline's
classifier learnt against the synthetic truth (:mod:`.outline_training`)."""
