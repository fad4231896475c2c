"""Pictures of a result: body poses from the stored model, the overlay video."""
