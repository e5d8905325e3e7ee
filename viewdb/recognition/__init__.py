"""From a photo to the objects it shows: image loading, segmentation, the plans' client
and server halves, the colour and shape re-rankings, and the query pipeline."""
