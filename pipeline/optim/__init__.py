"""The optimiser below the alignment and the refinement: Levenberg-Marquardt on the normal
equations (:mod:`pipeline.optim.lm`) and the residual-block vocabulary a measurement model
implements (:mod:`pipeline.optim.block`). numpy and scipy only."""
