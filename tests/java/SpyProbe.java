// Runs lcm-spy (lcm.spy.Spy, the program laserline-spy starts) in this JVM on a display, lets it
// receive for a while, then prints what its channel table shows (one line per channel: the table's
// cells separated by tabs, after a header line) and saves a screenshot of the screen, with the
// decoded fields of OPEN_CHANNEL in lcm-spy's viewer (what a double click on its row opens).
// Usage: SpyProbe LCM_URL SECONDS SCREENSHOT.png OPEN_CHANNEL
import java.awt.Component;
import java.awt.Container;
import java.awt.Rectangle;
import java.awt.Robot;
import java.awt.Toolkit;
import java.awt.Window;
import java.io.File;
import java.lang.reflect.Field;
import java.lang.reflect.Method;
import java.util.Map;
import javax.imageio.ImageIO;
import javax.swing.JTable;
import javax.swing.SwingUtilities;
import javax.swing.table.TableModel;

public class SpyProbe {
  static void collectTables(Component c, StringBuilder out) {
    if (c instanceof JTable) {
      TableModel model = ((JTable) c).getModel();
      StringBuilder header = new StringBuilder("columns");
      for (int col = 0; col < model.getColumnCount(); ++col)
        header.append('\t').append(model.getColumnName(col));
      out.append(header).append('\n');
      for (int row = 0; row < model.getRowCount(); ++row) {
        StringBuilder line = new StringBuilder("row");
        for (int col = 0; col < model.getColumnCount(); ++col)
          line.append('\t').append(model.getValueAt(row, col));
        out.append(line).append('\n');
      }
    }
    if (c instanceof Container) {
      for (Component child : ((Container) c).getComponents()) collectTables(child, out);
    }
  }

  public static void main(String[] args) throws Exception {
    if (args.length != 4) {
      System.err.println("usage: SpyProbe LCM_URL SECONDS SCREENSHOT.png OPEN_CHANNEL");
      System.exit(2);
    }
    final lcm.spy.Spy spy = new lcm.spy.Spy(args[0]);
    final long half = Long.parseLong(args[1]) * 500;
    Thread.sleep(half);
    // lcm-spy's double click: its viewer of the channel's decoded messages (package-private).
    Field channels = lcm.spy.Spy.class.getDeclaredField("channelMap");
    channels.setAccessible(true);
    final Object channel = ((Map<?, ?>) channels.get(spy)).get(args[3]);
    if (channel == null) {
      System.err.println("SpyProbe: lcm-spy has not seen channel " + args[3]);
      System.exit(1);
    }
    final Method open =
        lcm.spy.Spy.class.getDeclaredMethod("createViewer", Class.forName("lcm.spy.ChannelData"));
    open.setAccessible(true);
    SwingUtilities.invokeAndWait(() -> {
      try {
        open.invoke(spy, channel);
      } catch (ReflectiveOperationException e) {
        throw new RuntimeException(e);
      }
    });
    Thread.sleep(half);
    final StringBuilder out = new StringBuilder();
    SwingUtilities.invokeAndWait(() -> {
      for (Window window : Window.getWindows()) collectTables(window, out);
    });
    Rectangle screen = new Rectangle(Toolkit.getDefaultToolkit().getScreenSize());
    ImageIO.write(new Robot().createScreenCapture(screen), "png", new File(args[2]));
    System.out.print(out);
    System.out.flush();
    System.exit(0);
  }
}
