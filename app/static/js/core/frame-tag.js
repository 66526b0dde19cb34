// The frame tag: a vehicle frame's number, stamped into its own pixels. The contract and the
// encoder are app/protocol/frametag.py; the layout reaches the page as `config.protocol.frameTag`
// ({blocksPerWidth, markerBlocks, bits}) and is passed in here. The relay's worker reads each
// analysed frame's tag with it; tests/protocol/test_frametag_js.py checks that it reads what the
// Python encoder stamps. Pure, no DOM.

/** The side of a tag's square blocks on a frame `width` pixels wide (its top rows). */
export function tagBlockSize(layout, width) {
  return Math.floor(width / layout.blocksPerWidth);
}

/**
 * The frame number stamped into a width×height RGBA frame (`data`, row by row), or null when
 * the marker blocks do not read white, then black. Each block reads as the mean luminance of its
 * inner half, white from 128 up.
 */
export function decodeFrameTag(layout, width, height, data) {
  const { markerBlocks, bits } = layout;
  const b = tagBlockSize(layout, width);
  if (b < 2 || height < b) return null;
  const lo = Math.floor(b / 4);
  const hi = lo + Math.max(1, Math.floor(b / 2));
  const white = (i) => {
    let sum = 0;
    let n = 0;
    for (let y = lo; y < hi; y += 1) {
      for (let x = i * b + lo; x < i * b + hi; x += 1) {
        const k = (y * width + x) * 4;
        sum += 0.299 * data[k] + 0.587 * data[k + 1] + 0.114 * data[k + 2];
        n += 1;
      }
    }
    return sum / n >= 128;
  };
  if (!white(0)) return null;
  for (let i = 1; i < markerBlocks; i += 1) if (white(i)) return null;
  let value = 0;
  for (let i = markerBlocks; i < markerBlocks + bits; i += 1)
    value = value * 2 + (white(i) ? 1 : 0);
  return value;
}
