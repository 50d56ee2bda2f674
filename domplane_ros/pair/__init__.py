"""plane_pair: the plane pipeline on stereo image files (an adapter, like replay/ and ros/)."""
