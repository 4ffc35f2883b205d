"""The shared agent core: networks, augmentation, auxiliary objectives and the agent."""
