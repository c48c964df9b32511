"""The learned inverse model: encoding, augmentations, network, training and the model registry."""
