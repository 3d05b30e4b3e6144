"""What a clip shows, found without changing it: limbs by their shape (`limbs`), leading
rest-pose frames (`tpose`) and the figures of a result (`quality`)."""
