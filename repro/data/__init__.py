"""Layer 3: transitions and episodes. The online replay, offline datasets on disk (their manifest, import and
export formats, recording, summaries, reference scores) and the offline replay that loads them; the
``repro dataset`` commands."""
