"""The recording contract shared by every rig and the pipeline: channels, schemas,
integrity (CRCs and the content digest). Imports nothing of ``rig`` or ``stages``."""
